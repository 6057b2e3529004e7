"""Tables and plots of the levels benchmark: per-run CSV, per-level summary (CSV + Markdown; the floor's row first,
then its per-joint table and the joints it flags: floor.py), box plots of the per-trial joint error, free-energy
curves, and error-vs-noise / broken-sensor plots of the robustness sweeps."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyschema.evaluation.core.tables import markdown_table, write_csv
from bodyschema.evaluation.levels.floor import FLOOR_LABEL, UNOBSERVABLE_DEG, floor_markdown

MAIN_COLUMNS = ("joint_err_deg", "joint_err_median_deg", "ee_err_mm", "success", "all_joints_2deg",
                "evaluations_per_trial", "converged", "diverged", "wall_s")


def aggregate(rows: Sequence[Mapping]) -> list[dict]:
    """One row per level: the mean over runs of every numeric metric, and its std as `<metric>_std`."""
    table = []
    for level in dict.fromkeys(r["level"] for r in rows):
        mine = [r for r in rows if r["level"] == level]
        out = {"level": level, "runs": len(mine)}
        for key in mine[0]:
            if key in ("level", "run") or not isinstance(mine[0][key], (int, float)):
                continue
            values = np.array([r[key] for r in mine], dtype=float)
            out[key] = float(values.mean())
            if key in MAIN_COLUMNS and len(mine) > 1:
                out[f"{key}_std"] = float(values.std(ddof=1))
        table.append(out)
    return table


def markdown(table: Sequence[Mapping], columns: Sequence[str] = MAIN_COLUMNS, key: str = "level") -> str:
    """A Markdown table of the main metrics, mean ± std over runs, one row per value of `key`."""
    return markdown_table(table, columns, key)


def plot_boxes(per_trial: Mapping[str, np.ndarray], path: Path) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(1.6 + 1.2 * len(per_trial), 4))
    labels = list(per_trial)
    ax.boxplot([np.maximum(per_trial[k], 1e-9) for k in labels], showfliers=True)
    ax.set_xticks(range(1, len(labels) + 1), [k if k == FLOOR_LABEL else f"level {k}" for k in labels])
    ax.set_yscale("log")
    ax.axhline(1.0, color="grey", ls="--", lw=0.8, label="success threshold (1°)")
    ax.set_ylabel("final mean |joint error| (deg)")
    ax.legend(loc="upper left", fontsize=8)
    return save_figure(fig, path, dpi=120)


def plot_curves(curves: Mapping[str, np.ndarray], path: Path) -> Path:
    """Median and inter-quartile band of F(t) − F_final per level (trials that stopped hold their last F)."""
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(6, 4))
    for level, f in curves.items():                                       # (T, N), NaN once a trial stopped
        held = _hold_last(f)
        gap = np.maximum(held - held[-1], 1e-12)
        q25, q50, q75 = np.percentile(gap, [25, 50, 75], axis=1)
        steps = np.arange(len(q50))
        ax.plot(steps, q50, label=f"level {level}")
        ax.fill_between(steps, q25, q75, alpha=0.2)
    ax.set_yscale("log")
    ax.set_xlabel("update step")
    ax.set_ylabel("F − F_final (nats): median, IQR")
    ax.legend()
    return save_figure(fig, path, dpi=120)


def plot_sweep(rows: Sequence[Mapping], x: str, path: Path, y: str = "joint_err_deg", xlabel: str | None = None,
               ylabel: str | None = None) -> Path:
    """Error vs a swept quantity (noise σ), or a bar per case (broken sensor) when x is not numeric. The labels
    default to the column names; pass them with units (robustness does)."""
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(5, 3.5))
    xs = [r[x] for r in rows]
    ys = np.maximum([r[y] for r in rows], 1e-9)                           # log axis: an exact 0 shows at 1e-9
    if all(isinstance(v, (int, float)) for v in xs):
        ax.plot(xs, ys, "o-")
        ax.set_xlabel(xlabel or f"{x} ({rows[0].get('modality', '')})")
    else:
        ax.bar([str(v) for v in xs], ys)
        ax.set_xlabel(xlabel or x)
    ax.set_yscale("log")
    ax.set_ylabel(ylabel or y)
    return save_figure(fig, path, dpi=120)


def write_all(summary, curves: Mapping[str, np.ndarray], out: Path, plots: bool = True,
              notes: str = "", unobservable_deg: float = UNOBSERVABLE_DEG) -> dict[str, Path]:
    """CSVs, summary.md (the table with the floor's row first, the floor per joint with the joints above
    `unobservable_deg`, then `notes`) and the plots of a levels run in `out`."""
    out.mkdir(parents=True, exist_ok=True)
    floor = [summary.floor] if summary.floor else []
    paths = {"runs_csv": write_csv(summary.floor_rows + summary.rows, out / "runs.csv"),
             "summary_csv": write_csv(floor + summary.table, out / "summary.csv")}
    paths["summary_md"] = out / "summary.md"
    parts = [markdown(floor + summary.table)]
    if summary.floor:
        parts.append(floor_markdown(summary.floor, summary.table, unobservable_deg))
    parts.append(notes)
    paths["summary_md"].write_text("\n".join(f"{p.rstrip()}\n" for p in parts if p))
    if plots:
        paths["boxplot"] = plot_boxes(summary.per_trial, out / "levels_boxplot.png")
        if curves:
            paths["free_energy"] = plot_curves(curves, out / "levels_free_energy.png")
    return paths


def _hold_last(f: np.ndarray) -> np.ndarray:
    """Fill NaNs (a stopped trial) with the trial's last finite value. (T, N) → (T, N)"""
    held = f.copy()
    for t in range(1, len(held)):
        gone = np.isnan(held[t])
        held[t, gone] = held[t - 1, gone]
    return held
