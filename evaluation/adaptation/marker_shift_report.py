"""Metrics, tables and plots of the marker-shift experiment (evaluation/marker_shift.py).

Per episode: the seen shift d (px, marker − hand at the shift), how far the hand moved after it (mm, px; final
and largest), the measured correction −Δhand·d/|d|² (the fraction of the seen shift the hand undid: 0 vision
ignored, 1 the seen marker back on the goal) beside its linear prediction, final pixel errors of the seen marker
and of the hand to the goal, belief–encoder gap, settling time and motion in the last second (a limit cycle
shows there). Summary: mean per (shift, visual precision) over the episodes that did not fail.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.tables import markdown_table, write_csv

SUMMARY_COLUMNS = ("seen_shift_px", "hand_move_mm", "hand_move_px", "correction", "predicted_correction",
                   "marker_err_px", "hand_err_px", "hand_err_mm", "settle_s", "late_motion_mm")
LATE_WINDOW_S = 1.0        # s at the end of an episode where remaining motion means "not settled"
SETTLE_BAND = (0.1, 0.5)   # settled: within max(10 % of the final displacement, 0.5 mm) of the final hand position


def predicted_correction(jac_px: np.ndarray, seen_shift: np.ndarray, visual_precision: float,
                         joint_precision: float) -> np.ndarray:
    """Linear steady state of the hand pixel error e = −(I + C)⁻¹ C d, C = (Π_v/Π_q) J Jᵀ; returns −e·d/|d|² (B,).

    At rest ȧ = 0: Π_q (q − μ) = −Jᵀ Π_v (m − g(μ)); added to perception's ∂F/∂μ = 0 it leaves the
    attractor alone, so g(μ) = x_d; with m = h + d and h − x_d ≈ J (q − μ): e = −C (e + d).
    jac_px (B, 2, Dq) px/rad at the goal, seen_shift d (B, 2) px; NaN where d = 0.
    """
    c = (visual_precision / joint_precision) * jac_px @ np.swapaxes(jac_px, 1, 2)          # (B, 2, 2)
    e = -np.linalg.solve(np.eye(2) + c, (c @ seen_shift[..., None]))[..., 0]               # (B, 2) px
    norm2 = (seen_shift ** 2).sum(1)
    return np.where(norm2 > 0, -(e * seen_shift).sum(1) / np.where(norm2 > 0, norm2, 1.0), np.nan)


def episode_rows(series: Mapping[str, np.ndarray], shifts: Sequence[str], visual_precision: float,
                 predicted: np.ndarray) -> list[dict]:
    """One row per episode of a simulated batch (marker_shift.simulate); `shifts` names each episode's shift."""
    k, t = int(series["shift_tick"]), series["t"]
    hand, hand_px, marker_px = series["hand_xyz"], series["hand_px"], series["marker_px"]   # (T+1, B, ·)
    d = marker_px[k] - hand_px[k]                                                           # (B, 2) px
    move_px = hand_px[-1] - hand_px[k]
    norm2 = (d ** 2).sum(1)
    correction = np.where(norm2 > 0, -(move_px * d).sum(1) / np.where(norm2 > 0, norm2, 1.0), np.nan)
    from_end = 1e3 * np.linalg.norm(hand - hand[-1], axis=2)                                # (T+1, B) mm
    moved = 1e3 * np.linalg.norm(hand[k:] - hand[k], axis=2)                                # (T+1−k, B) mm
    band = np.maximum(SETTLE_BAND[0] * moved[-1], SETTLE_BAND[1])
    late = t >= t[-1] - LATE_WINDOW_S
    rows = []
    for i, shift in enumerate(shifts):
        outside = np.flatnonzero(from_end[k:, i] > band[i])
        rows.append({
            "shift": shift, "visual_precision": float(visual_precision), "episode": i,
            "seen_shift_px": float(np.sqrt(norm2[i])),
            "hand_move_mm": float(moved[-1, i]), "hand_move_max_mm": float(moved[:, i].max()),
            "hand_move_px": float(np.linalg.norm(move_px[i])),
            "correction": float(correction[i]), "predicted_correction": float(predicted[i]),
            "marker_err_px": float(np.linalg.norm(marker_px[-1, i] - series["goal_px"][i])),
            "hand_err_px": float(np.linalg.norm(hand_px[-1, i] - series["goal_px"][i])),
            "hand_err_mm": float(1e3 * np.linalg.norm(hand[-1, i] - series["goal_xyz"][i])),
            "hold_drift_mm": float(1e3 * np.linalg.norm(hand[:k + 1, i] - series["goal_xyz"][i], axis=1).max()),
            "belief_gap_deg": float(np.rad2deg(np.abs(series["belief"][-1, i] - series["q"][-1, i])).mean()),
            "settle_s": float(t[k + outside[-1] + 1] - t[k]) if outside.size else 0.0,
            "late_motion_mm": float(from_end[late, i].max()),
            "failed": bool(series["failed"][i]), "reason": str(series["reasons"][i])})
    return rows


def summarize(rows: Sequence[Mapping]) -> list[dict]:
    """Mean per (shift, visual precision) over episodes that did not fail; `failed` counts the others."""
    table = []
    for key in dict.fromkeys((r["shift"], r["visual_precision"]) for r in rows):
        mine = [r for r in rows if (r["shift"], r["visual_precision"]) == key]
        ok = [r for r in mine if not r["failed"]]
        out = {"shift": key[0], "visual_precision": key[1], "episodes": len(mine), "failed": len(mine) - len(ok)}
        for c in (*SUMMARY_COLUMNS, "hand_move_max_mm", "hold_drift_mm", "belief_gap_deg"):
            values = np.array([r[c] for r in ok], dtype=float)
            out[c] = float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")
        table.append(out)
    return table


def markdown(table: Sequence[Mapping], note: str) -> str:
    columns = ("visual_precision", "episodes", "failed", *SUMMARY_COLUMNS)
    return markdown_table(table, columns, "shift", digits=3) + "\n" + note + "\n"


def mean_curves(batches: Mapping[float, Mapping[str, np.ndarray]], shifts: Sequence[str]) -> list[dict]:
    """Long table (shift, visual_precision, t) → mean over non-failed episodes of the errors and hand displacement."""
    rows = []
    for precision, s in batches.items():
        ok = ~s["failed"]
        marker_err = np.linalg.norm(s["marker_px"] - s["goal_px"], axis=2)                  # (T+1, B) px
        hand_err = np.linalg.norm(s["hand_px"] - s["goal_px"], axis=2)                      # (T+1, B) px
        moved = 1e3 * np.linalg.norm(s["hand_xyz"] - s["goal_xyz"], axis=2)                 # (T+1, B) mm
        for shift in dict.fromkeys(shifts):
            cols = np.array([sh == shift for sh in shifts]) & ok
            if not cols.any():
                continue
            for j, t in enumerate(s["t"]):
                rows.append({"shift": shift, "visual_precision": float(precision), "t_s": float(t),
                             "marker_err_px": float(marker_err[j, cols].mean()),
                             "hand_err_px": float(hand_err[j, cols].mean()),
                             "hand_displacement_mm": float(moved[j, cols].mean())})
    return rows


# ---- outputs -----------------------------------------------------------------------------------------------
def plot_over_time(curves: Sequence[Mapping], shift_time: float, path: Path, what: str) -> Path:
    """One panel per shift: `what` (pixel errors, or hand displacement) vs time, one colour per visual precision."""
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    shifts = list(dict.fromkeys(r["shift"] for r in curves))
    precisions = list(dict.fromkeys(r["visual_precision"] for r in curves))
    fig, axes = plt.subplots(1, len(shifts), figsize=(3.6 * len(shifts), 3.4), squeeze=False, sharey=True)
    for ax, shift in zip(axes[0], shifts):
        for n, p in enumerate(precisions):
            mine = [r for r in curves if r["shift"] == shift and r["visual_precision"] == p]
            t = [r["t_s"] for r in mine]
            colour = f"C{n}"
            if what == "error":
                ax.plot(t, [r["marker_err_px"] for r in mine], color=colour, label=f"seen marker, Π_v={p:g}")
                ax.plot(t, [r["hand_err_px"] for r in mine], color=colour, ls="--", label=f"hand, Π_v={p:g}")
            else:
                ax.plot(t, [r["hand_displacement_mm"] for r in mine], color=colour, label=f"Π_v={p:g}")
        ax.axvline(shift_time, color="grey", ls=":", lw=1)
        ax.set(title=f"shift: {shift}", xlabel="time (s)")
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("pixel error to goal (px)" if what == "error" else "hand displacement from goal (mm)")
    axes[0, -1].legend(fontsize=7)
    return save_figure(fig, path, dpi=120)


def plot_image_paths(batches: Mapping[float, Mapping[str, np.ndarray]], shifts: Sequence[str],
                     image_size: tuple[int, int], path: Path) -> Path:
    """Image plane, the first episode of each shift: hand (dashed) and seen marker (solid, from the shift on; ○ where
    it was seen just after the shift) paths, final positions (•), goal (×)."""
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    names = list(dict.fromkeys(shifts))
    fig, axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 3.4), squeeze=False)
    for ax, shift in zip(axes[0], names):
        i = list(shifts).index(shift)
        for n, (p, s) in enumerate(batches.items()):
            k = int(s["shift_tick"])
            ax.plot(*s["marker_px"][k:, i].T, color=f"C{n}", lw=1.2, label=f"seen marker, Π_v={p:g}")
            ax.plot(*s["hand_px"][:, i].T, color=f"C{n}", lw=1.0, ls="--", label=f"hand, Π_v={p:g}")
            ax.plot(*s["marker_px"][k, i], "o", mfc="none", color=f"C{n}", ms=6)
            ax.plot(*s["marker_px"][-1, i], "o", color=f"C{n}", ms=3)
            ax.plot(*s["hand_px"][-1, i], "o", color=f"C{n}", ms=3)
        goal = next(iter(batches.values()))["goal_px"][i]
        ax.plot(*goal, "kx", ms=8, label="goal")
        ax.set(title=f"shift: {shift}", xlabel="u (px)", ylabel="v (px)", aspect="equal")
        ax.invert_yaxis()                                   # image rows grow downwards
        ax.grid(alpha=0.3)
    axes[0, -1].legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0))   # outside: paths fill the box
    fig.suptitle(f"image plane ({image_size[1]}×{image_size[0]} px camera), first goal pose", fontsize=9)
    return save_figure(fig, path, dpi=120)


def plot_correction(table: Sequence[Mapping], path: Path) -> Path:
    """Measured vs predicted correction against visual precision, one line per shift: the trust trade-off."""
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(5, 3.6))
    for n, shift in enumerate(dict.fromkeys(r["shift"] for r in table)):
        mine = [r for r in table if r["shift"] == shift and np.isfinite(r["correction"])]
        if not mine:
            continue
        p = [r["visual_precision"] for r in mine]
        ax.plot(p, [r["correction"] for r in mine], "o-", color=f"C{n}", label=f"{shift} (measured)")
        ax.plot(p, [r["predicted_correction"] for r in mine], ":", color=f"C{n}", label=f"{shift} (linear theory)")
    ax.set(xscale="log", xlabel="visual precision Π_v (px⁻²)", ylabel="correction (fraction of seen shift undone)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path, dpi=120)


def _row_label(row: Mapping) -> str:
    """A summary row's name in MLflow metrics: its shift and visual precision."""
    return f"{row['shift']}.pv{row['visual_precision']:g}"


def write_all(config, out: Path, robot, models, rows: list[dict], batches: dict, shifts: list[str]
              ) -> dict[str, Path]:
    """summary.md/csv, per-episode and mean time-series CSVs, plots into the run folder `out`; then the models, one
    MLflow run if asked and the latest link."""
    table = summarize(rows)
    curves = mean_curves(batches, shifts)
    note = (f"nao_arm holds {config.trials} held-out goals ({config.goal}) by active inference; at "
            f"t = {config.shift_time:g} s the visual marker moves {config.offset * 1e3:g} mm in the hand frame "
            f"(forearm: 2×). Means over episodes at t = {config.duration:g} s: hand displacement after the shift, "
            "correction = fraction of the seen shift the hand undid (linear theory beside it), final pixel errors "
            "of the seen marker and the hand to the goal, settling time, hand motion in the last second.")
    paths = {"summary_md": out / "summary.md",
             "summary_csv": write_csv(table, out / "summary.csv"),
             "episodes_csv": write_csv(rows, out / "episodes.csv"),
             "timeseries_csv": write_csv(curves, out / "timeseries.csv"),
             "error_png": plot_over_time(curves, config.shift_time, out / "error_vs_time.png", "error"),
             "displacement_png": plot_over_time(curves, config.shift_time, out / "displacement_vs_time.png",
                                                "displacement"),
             "image_paths_png": plot_image_paths(batches, shifts, robot.image_size, out / "image_paths.png"),
             "correction_png": plot_correction(table, out / "correction_vs_precision.png")}
    paths["summary_md"].write_text(markdown(table, note))
    publish(config, out, "marker_shift", table_metrics(table, _row_label), paths, models)
    return paths
