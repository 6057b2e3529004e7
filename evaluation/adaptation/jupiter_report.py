"""Tables and plots of the Jupiter experiment (adaptation/jupiter.py): per-controller summary (steady error before
and after the gravity switch, peak, settle time), episode and time-series CSVs, error-vs-time and joint plots."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bodyschema.datagen.body.record import load_record
from bodyschema.datagen.body.robot import GRAVITY
from bodyschema.evaluation.core.tables import markdown_table, write_csv

SUMMARY_COLUMNS = ("joint_err_before_deg", "joint_err_after_deg", "joint_peak_after_deg", "settle_s",
                   "ee_err_before_mm", "ee_err_after_mm", "ee_peak_after_mm")


@dataclass
class ControllerRun:               # one controller's episodes
    name: str
    t: np.ndarray                  # (T,) s
    q: np.ndarray                  # (T, B, Dq) rad
    joint: np.ndarray              # (T, B) deg
    ee: np.ndarray                 # (T, B) mm
    rows: list[dict] = field(default_factory=list)


def summarize(runs: Sequence[ControllerRun]) -> list[dict]:
    """One row per controller: the mean over its non-failed episodes; settle_s over the episodes that settled."""
    table = []
    for run in runs:
        ok = [r for r in run.rows if not r["failed"]]
        row = {"controller": run.name, "episodes": len(run.rows), "failed": len(run.rows) - len(ok)}
        for key in SUMMARY_COLUMNS:
            values = np.array([r[key] for r in ok], dtype=float)
            row[key] = float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")
        row["settled"] = float(np.mean([np.isfinite(r["settle_s"]) for r in ok])) if ok else float("nan")
        table.append(row)
    return table


def markdown(table: Sequence[dict], config) -> str:
    lines = markdown_table(table, (*SUMMARY_COLUMNS, "settled", "failed"), "controller", digits=3).splitlines()
    aic, pd = config.aic, config.pd
    kp = pd.kp if pd.kp is not None else load_record(config.robot).pd["kp"]   # None: the robot record's [pd]
    return "\n".join([
        f"# Jupiter: gravity {GRAVITY} → {config.jupiter_gravity} m/s² at t = {config.switch_time} s "
        f"(torque {config.robot})",
        "", *lines, "",
        f"{config.trials} episodes hold random joint goals (ready pose ± {config.spread} rad) at "
        f"{config.control_rate:g} Hz; joint error = mean |q − q_d| over joints. before / after: mean error over the "
        f"last {config.steady_window} s before the switch / of the run; peak: after the switch.",
        f"settle_s: time after the switch until the joint error stays below {config.settle_deg}° (mean over the "
        "episodes that settled, `settled` = their fraction).",
        f"Gains: PD K_p = {'/'.join(f'{k:g}' for k in kp)} N·m/rad plus Earth-gravity compensation; AIC "
        f"κ_a Π_q̇ = {aic.k_a * aic.pi_qd:g} N·m/rad (acts as P) and κ_a Π_q = {aic.k_a * aic.pi_q:g} N·m/(rad·s) "
        "(integral).", ""])


def plot_errors(runs: Sequence[ControllerRun], config, path: Path) -> Path:
    """Median and inter-quartile band over episodes of the joint and ee error vs time, the switch marked."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for ax, key, unit in ((axes[0], "joint", "deg"), (axes[1], "ee", "mm")):
        for run in runs:
            err = np.maximum(getattr(run, key), 1e-4)                       # (T, B); log axis floor
            q25, q50, q75 = np.nanpercentile(err, [25, 50, 75], axis=1)
            ax.plot(run.t, q50, label=run.name)
            ax.fill_between(run.t, q25, q75, alpha=0.2)
        ax.axvline(config.switch_time, color="k", ls="--", lw=0.8, label=f"g → {config.jupiter_gravity} m/s²")
        ax.set(yscale="log", xlabel="time (s)", ylabel=f"{key} error ({unit}), median and IQR")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return save_figure(fig, path)


def plot_trajectories(runs: Sequence[ControllerRun], goal: np.ndarray, config, path: Path) -> Path:
    """Every joint of episode 0 under each controller, the goal dashed, the switch marked."""
    from bodyschema.evaluation.core.plots import plt, save_figure
    dq = len(goal)
    fig, axes = plt.subplots(2, (dq + 1) // 2, figsize=(3.2 * ((dq + 1) // 2), 6), squeeze=False)
    for j, ax in enumerate(axes.flat):
        if j >= dq:
            ax.axis("off")
            continue
        for run in runs:
            ax.plot(run.t, np.rad2deg(run.q[:, 0, j]), label=run.name, lw=1)
        ax.axhline(np.rad2deg(goal[j]), color="k", ls=":", lw=0.8)
        ax.axvline(config.switch_time, color="k", ls="--", lw=0.6)
        ax.set(title=f"joint{j + 1}", xlabel="time (s)", ylabel="q (deg)")
    axes.flat[0].legend(fontsize=7)
    return save_figure(fig, path)


def write_report(runs: Sequence[ControllerRun], goals: np.ndarray, config, out: Path) -> dict[str, Path]:
    """Tables and plots of a JupiterConfig run into its run folder `out`."""
    table = summarize(runs)
    paths = {"summary_csv": write_csv(table, out / "summary.csv"),
             "episodes_csv": write_csv([r for run in runs for r in run.rows], out / "episodes.csv")}
    every = max(1, int(round(0.01 * config.control_rate)))                 # 100 Hz time series
    series = [{"controller": run.name, "t_s": float(run.t[i]), "joint_err_deg_median": float(np.median(run.joint[i])),
               "ee_err_mm_median": float(np.median(run.ee[i]))} for run in runs for i in range(0, len(run.t), every)]
    paths["timeseries_csv"] = write_csv(series, out / "timeseries.csv")
    paths["summary_md"] = out / "summary.md"
    paths["summary_md"].write_text(markdown(table, config))
    paths["errors_png"] = plot_errors(runs, config, out / "errors.png")
    paths["trajectories_png"] = plot_trajectories(runs, goals[0], config, out / "trajectories.png")
    return paths
