"""Tables, plots and the summary of the rubber-hand benchmark, beside the drift reported for people."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bodyschema.evaluation.core.plots import plt, save_figure
from bodyschema.evaluation.core.tables import markdown_table, write_csv

# What people show (README "Rubber-hand drift" for the references): the order of magnitude the robot's drift is
# read against. Only directions are asserted here; look up exact values in the papers.
HUMAN_REFERENCE = (
    "People (Botvinick & Cohen 1998; Tsakiris & Haggard 2005; Rohde, Di Luca & Ernst 2011): the felt hand drifts "
    "towards a rubber hand seen 15–30 cm away by a few cm, a fraction of the displacement, more after synchronous "
    "than after continuous asynchronous stroking; the drift builds up over tens of seconds to minutes and "
    "can appear without touch (vision alone, Rohde 2011), the illusion weakening as the hands are set further apart.")


STYLE = {"synchronous": "-", "asynchronous": "--", "vision_only": ":"}     # line style per stroking mode


def condition_table(config, episodes, drift: np.ndarray, failed: np.ndarray) -> tuple[list[dict], list[dict]]:
    """One row per condition (final drift, its fraction of the displacement, q(own), time to half the final drift)
    and one per condition and frame (mean drift over time)."""
    rows, over_time = [], []
    for c, (disp, sigma, mode) in enumerate(config.conditions()):
        sel = (episodes.condition == c) & ~failed
        label = f"d={disp * 100:g}cm σ={sigma * 100:g}cm {mode}"
        mean = np.nanmean(drift[sel], axis=0) if sel.any() else np.full(drift.shape[1], np.nan)   # (T,) m
        final = final_drift(drift[sel], episodes.times, config.final_window_s)          # (n,) m
        rows.append({"condition": label, "displacement_cm": disp * 100, "visual_sigma_cm": sigma * 100,
                     "mode": mode, "drift_cm": float(np.mean(final) * 100) if sel.any() else float("nan"),
                     "drift_cm_std": float(np.std(final) * 100) if sel.any() else float("nan"),
                     "drift_fraction": float(np.mean(final) / disp) if sel.any() else float("nan"),
                     "own": float(np.mean(episodes.own[sel, -1])) if sel.any() else float("nan"),
                     "t_half_s": _time_to_half(mean, episodes.times), "episodes": int(sel.sum()),
                     "failed": int(((episodes.condition == c) & failed).sum())})
        over_time += [{"condition": label, "t_s": float(t), "drift_cm": float(m * 100),
                       "own": float(np.mean(episodes.own[sel, f])) if sel.any() else float("nan")}
                      for f, (t, m) in enumerate(zip(episodes.times, mean))]
    return rows, over_time


def final_drift(drift: np.ndarray, times: np.ndarray, window_s: float) -> np.ndarray:
    """(N,) m: each episode's drift (N, T) averaged over the frames of the last `window_s` s."""
    return drift[:, times > times[-1] - window_s].mean(axis=1)


def _time_to_half(mean: np.ndarray, times: np.ndarray) -> float:
    """s until the mean drift first reaches half its final value (NaN when it does not build up: the final value
    is not above twice the first frame's, as with asynchronous stroking)."""
    if not np.isfinite(mean[-1]) or mean[-1] <= 2 * abs(mean[0]):
        return float("nan")
    return float(times[np.argmax(mean >= 0.5 * mean[-1])])


def write_report(out: Path, config, robot: str, visual, episodes, drift, failed, rows, over_time, wall: float
                 ) -> dict[str, Path]:
    paths = {"conditions_csv": write_csv(rows, out / "conditions.csv"),
             "over_time_csv": write_csv(over_time, out / "over_time.csv")}
    conditions = config.conditions()
    per_episode = [{"episode": i, "condition": int(c), "displacement_cm": conditions[c][0] * 100,
                    "visual_sigma_cm": conditions[c][1] * 100, "mode": conditions[c][2], "failed": bool(f),
                    "drift_cm": float(d * 100), "own": float(o)}
                   for i, (c, f, d, o) in enumerate(zip(episodes.condition, failed,
                                                        final_drift(drift, episodes.times, config.final_window_s),
                                                        episodes.own[:, -1]))]
    paths["episodes_csv"] = write_csv(per_episode, out / "episodes.csv")
    columns = ("drift_cm", "drift_fraction", "own", "t_half_s", "episodes", "failed")
    lines = [f"# Rubber-hand drift ({robot}, models: {', '.join(['joints', *visual])})", "",
             f"{config.trials} episodes per condition, {config.duration:g} s of stroking at "
             f"{config.stroke_rate_hz:g} Hz (asynchronous: {config.async_lag_s:g} s late), proprioception σ "
             f"{np.degrees(config.proprio_noise):.3g}°, frames every {config.period:g} s; drift = the belief's hand "
             f"moved towards the seen hand over the last {config.final_window_s:g} s (cm, ± std over episodes), "
             "as a fraction of the displacement; "
             "own = q(the seen hand is mine); t_half_s = time to half the final mean drift.", "",
             markdown_table(rows, columns, "condition", digits=3), HUMAN_REFERENCE, "",
             f"Wall time {wall:.1f} s."]
    paths["summary"] = out / "summary.md"
    paths["summary"].write_text("\n".join(lines) + "\n", encoding="utf-8")
    if config.plots:
        paths.update(_plots(out, config, rows, over_time))
    return paths


def _plots(out: Path, config, rows, over_time) -> dict[str, Path]:
    paths = {}
    fig, ax = plt.subplots(figsize=(6, 4))
    disp = config.displacements[len(config.displacements) // 2]
    for row in rows:
        if row["displacement_cm"] != disp * 100:
            continue
        series = [r for r in over_time if r["condition"] == row["condition"]]
        color = f"C{np.abs(np.array(config.visual_sigmas) * 100 - row['visual_sigma_cm']).argmin() % 10}"  # per σ
        ax.plot([r["t_s"] for r in series], [r["drift_cm"] for r in series], STYLE[row["mode"]], color=color,
                label=f"σ={row['visual_sigma_cm']:g}cm {row['mode']}")
    ax.set(xlabel="stroking time (s)", ylabel="drift towards the seen hand (cm)",
           title=f"Drift over time, seen hand {disp * 100:g} cm away")
    ax.legend(fontsize=7)
    paths["drift_over_time_png"] = save_figure(fig, out / "drift_over_time.png")
    fig, ax = plt.subplots(figsize=(6, 4))
    for d in config.displacements:
        for mode in config.modes:
            sel = [r for r in rows if r["displacement_cm"] == d * 100 and r["mode"] == mode]
            ax.plot([r["visual_sigma_cm"] for r in sel], [r["drift_fraction"] for r in sel],
                    STYLE[mode], marker="o", color=f"C{config.displacements.index(d) % 10}",
                    label=f"{d * 100:g} cm {mode}")
    ax.set(xscale="log", xlabel="visual σ (cm): lower = more precise", ylabel="final drift / displacement",
           title="Drift vs visual precision")
    ax.legend(fontsize=7)
    paths["drift_vs_precision_png"] = save_figure(fig, out / "drift_vs_precision.png")
    return paths
