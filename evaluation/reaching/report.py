"""Metrics, tables, plots and the MLflow run of the reaching benchmark (reaching/benchmark.py).

Writes into the run folder: `reaching_episodes.csv` (one row per controller × target), `summary.csv` and `summary.md`
(one row per controller), `ee_error.png` (ee error vs time, every target and the mean, per controller) and
`image_paths.png` (the ee path in the camera image for a few targets).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from bodyschema.base.modalities import get, is_image
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.sensing import sense
from bodyschema.evaluation.core.tables import markdown_table, write_csv
from bodyschema.evaluation.reaching import goal_pose

SUMMARY_COLUMNS = ("episodes", "success", "goal_success", "ee_err_mm", "ee_err_median_mm", "joint_err_deg",
                   "time_to_reach_s", "failed", "wall_s")


def time_to_reach(t: np.ndarray, err: np.ndarray, tolerance: float) -> np.ndarray:
    """First time from which the error stays below tolerance to the end; NaN if it never does. t (T,), err (T, B)."""
    inside = err < tolerance                                              # (T, B)
    stays = np.flip(np.logical_and.accumulate(np.flip(inside, 0), 0), 0)   # inside from here to the end
    first = np.argmax(stays, axis=0)
    return np.where(stays.any(axis=0), t[first], np.nan)


def goal_errors(config, robot, modality: str, goal: torch.Tensor, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Final error in the goal's own space and whether it is within the goal tolerance. q (B, Dq) rad → (B,), (B,)"""
    lim = robot.joint_limits
    q = np.clip(q, lim[:, 0], lim[:, 1])
    x = goal.numpy()
    if modality == "joints":
        err = np.rad2deg(np.abs(q - x)).mean(axis=1)
        return err, err < 1.0
    reached = sense(robot, modality, q)                                   # what the goal sensor reads at q
    if modality == "ee_xyz":
        err = 1e3 * np.linalg.norm(reached - x, axis=1)
        return err, err < config.success_mm
    if modality == "ee_pixel":
        err = np.linalg.norm(reached - x, axis=1)
        return err, err < config.pixel_tolerance
    err = ((reached - x) ** 2).reshape(len(q), -1).mean(axis=1)
    return err, err < config.image_mse_threshold


def episode_rows(config, robot, modality, episodes, name: str, result) -> list[dict]:
    tol = config.success_mm * 1e-3
    reach = time_to_reach(result.t, result.ee_err, tol)
    final = result.ee_err[-1]                                             # (B,) m
    joint = np.rad2deg(np.abs(result.q - episodes.q_target)).mean(axis=1)
    goal_err, goal_ok = goal_errors(config, robot, modality, episodes.goal[modality], result.q)
    imagined = episodes.extra.get("imagined") if name == "aif" else None
    imagined_mm = None if imagined is None else goal_pose.imagined_error_mm(robot, episodes, imagined)   # (B,)
    rows = []
    for i in range(len(final)):
        rows.append({"controller": name, "target": i, "success": bool(final[i] < tol and not result.failed[i]),
                     "ee_err_mm": 1e3 * float(final[i]), "joint_err_deg": float(joint[i]),
                     "time_to_reach_s": float(reach[i]), f"goal_err_{get(modality).reported_unit}": float(goal_err[i]),
                     "goal_success": bool(goal_ok[i] and not result.failed[i]), "failed": bool(result.failed[i]),
                     "reason": result.reasons[i] or ""})
        if imagined_mm is not None:
            rows[-1]["imagined_ee_err_mm"] = float(imagined_mm[i])
    return rows


def summarize(rows: list[dict], walls: dict[str, float]) -> list[dict]:
    table = []
    for name in dict.fromkeys(r["controller"] for r in rows):
        mine = [r for r in rows if r["controller"] == name]
        ee = np.array([r["ee_err_mm"] for r in mine])
        reached = np.array([r["time_to_reach_s"] for r in mine])
        table.append({"controller": name, "episodes": len(mine),
                      "success": float(np.mean([r["success"] for r in mine])),
                      "goal_success": float(np.mean([r["goal_success"] for r in mine])),
                      "ee_err_mm": float(ee.mean()), "ee_err_median_mm": float(np.median(ee)),
                      "joint_err_deg": float(np.mean([r["joint_err_deg"] for r in mine])),
                      "time_to_reach_s": float(np.nanmean(reached)) if np.isfinite(reached).any() else float("nan"),
                      "failed": int(sum(r["failed"] for r in mine)), "wall_s": float(walls[name])})
        imagined = [r["imagined_ee_err_mm"] for r in mine if "imagined_ee_err_mm" in r]
        if imagined:
            table[-1]["imagined_ee_err_mm"] = float(np.median(imagined))
    return table


def markdown(table: list[dict], config, modality: str, robot_name: str) -> str:
    tol = f"image MSE {config.image_mse_threshold:g}" if is_image(modality) else {
        "ee_pixel": f"{config.pixel_tolerance:g} px", "ee_xyz": f"{config.success_mm:g} mm", "joints": "1°"}[modality]
    text = (f"Reaching on {robot_name}: {table[0]['episodes']} random reachable targets, {modality} goals, "
            f"{config.seconds:g} s at {config.rate:g} Hz, seed {config.seed}. `success`: final simulator "
            f"ee error < {config.success_mm:g} mm; `goal_success`: final error in the goal space < {tol}; "
            "`time_to_reach_s`: mean over the episodes that reached and stayed. "
            "aif = active inference, pd = the baseline on the target's true joint pose (position servos: plus "
            "their gravity feed-forward; torque motors: PD + model compensation).")
    if "imagined_ee_err_mm" in table[0]:
        text += (" The AIF first inferred each goal's pose in imagination (goal inference, then a joint-space "
                 "attractor); `imagined_ee_err_mm`: median ee error of that pose.")
    if modality == "ee_pixel":
        text += " A pixel goal fixes the ray, not the depth: `success` can fail where `goal_success` holds."
    if config.noise or config.broken or config.frozen:
        text += f" Noise σ {dict(config.noise)}, broken {list(config.broken)}, frozen {list(config.frozen)}."
    columns = SUMMARY_COLUMNS + (("imagined_ee_err_mm",) if "imagined_ee_err_mm" in table[0] else ())
    return markdown_table(table, columns, "controller") + "\n" + text + "\n"


def plot_errors(results: dict, path: Path, success_mm: float) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure
    fig, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 3.8), squeeze=False, sharey=True)
    for ax, (name, res) in zip(axes[0], results.items()):
        err = np.maximum(1e3 * res.ee_err, 1e-3)                          # (T+1, B) mm, floor for the log axis
        ax.plot(res.t, err, color="tab:blue", lw=0.5, alpha=0.3)
        ax.plot(res.t, err.mean(axis=1), color="k", lw=2, label="mean")
        ax.axhline(success_mm, color="tab:red", ls="--", lw=1, label=f"{success_mm:g} mm")
        ax.set(yscale="log", xlabel="time (s)", title=name)
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("ee error (mm)")
    return save_figure(fig, path)


def plot_paths(results: dict, goal_px: np.ndarray, robot, path: Path, n: int) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure
    h, w = robot.image_size
    fig, axes = plt.subplots(1, len(results), figsize=(4.5 * len(results), 4.5 * h / w + 0.6), squeeze=False)
    colors = plt.get_cmap("tab10").colors
    for ax, (name, res) in zip(axes[0], results.items()):
        for i in range(min(n, res.ee_pixel.shape[1])):
            c = colors[i % len(colors)]
            ax.plot(res.ee_pixel[:, i, 0], res.ee_pixel[:, i, 1], color=c, lw=1)
            ax.plot(*res.ee_pixel[0, i], "o", color=c, ms=4)
            ax.plot(*goal_px[i], "x", color=c, ms=8, mew=2)
        ax.set(xlim=(0, w - 1), ylim=(h - 1, 0), aspect="equal", xlabel="u (px)", ylabel="v (px)",
               title=f"{name}: ee path (o start, x goal)")
    return save_figure(fig, path)


def write_all(config, out: Path, robot, models, modality, episodes, results: dict, walls: dict) -> dict:
    """Tables and plots into the run folder `out`, then the models, the MLflow run and the latest link."""
    rows = [r for name, res in results.items() for r in episode_rows(config, robot, modality, episodes, name, res)]
    table = summarize(rows, walls)
    paths = {"episodes_csv": write_csv(rows, out / "reaching_episodes.csv"),
             "summary_csv": write_csv(table, out / "summary.csv"),
             "summary_md": out / "summary.md"}
    paths["summary_md"].write_text(markdown(table, config, modality, robot.name))
    paths["ee_error_png"] = plot_errors(results, out / "ee_error.png", config.success_mm)
    goal_px = robot.project(episodes.target_xyz)
    paths["paths_png"] = plot_paths(results, goal_px, robot, out / "image_paths.png", config.path_plots)
    publish(config, out, "reaching", table_metrics(table, "controller"), paths, models)
    return paths
