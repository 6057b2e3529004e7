"""How a levels row is scored from the final beliefs of one inference: joint error (deg, per joint and mean),
end-effector error (mm, simulator FK at the belief), image MSE with an image model, success, steps, convergence and
cost. One scorer for the level rows (benchmark.py) and the floor (floor.py)."""

from __future__ import annotations

import numpy as np
import torch

from bodyschema.base.modalities import is_image
from bodyschema.evaluation.levels.run_batch import RunBatch, split_result


def score(models, robot, targets, label: str, result, evaluations: int, wall: float, success_deg: float):
    """The metrics row of a level's final beliefs and its per-trial arrays (deg, mm)."""
    mu = result.mu.numpy()                                                 # (N, Dq) rad
    err = np.rad2deg(np.abs(mu - targets.q))                               # (N, Dq) deg
    mean_err = err.mean(axis=1)
    lim = robot.joint_limits
    ee_mm = 1e3 * np.linalg.norm(robot.fk(np.clip(mu, lim[:, 0], lim[:, 1])) - robot.fk(targets.q), axis=1)
    row = {"level": label,
           "trials": len(mu),
           "joint_err_deg": float(mean_err.mean()), "joint_err_median_deg": float(np.median(mean_err)),
           **{f"joint_err_deg/{name}": float(e) for name, e in zip(robot.joint_names, err.mean(axis=0))},
           "ee_err_mm": float(ee_mm.mean()), "success": float((mean_err < success_deg).mean()),
           "all_joints_2deg": float((err <= 2.0).all(axis=1).mean()),   # Pixel-AIF's criterion: every joint ≤ 2°
           "steps": float(result.steps.double().mean()), "converged": float(result.converged.double().mean()),
           "diverged": int(result.n_diverged), "evaluations_per_trial": evaluations / len(mu), "wall_s": wall}
    image = next((m for m in models if is_image(m.modality)), None)
    if image is not None:
        with torch.no_grad():
            pred = image.predict(result.mu.to(torch.float32)).double()
        row["image_mse"] = float((pred - torch.from_numpy(targets.observations[image.modality])).pow(2).mean())
    return row, {"mean_err_deg": mean_err, "ee_err_mm": ee_mm}


def score_runs(models, robot, batch: RunBatch, label: str, result, evaluations: float, wall: float,
               success_deg: float) -> list[tuple[dict, dict, object]]:
    """Each run's (row, per-trial arrays, result) from a batched result: its trials, and its share by trials of the
    batch's evaluations and wall time."""
    out, total = [], len(batch.targets.q)
    for i, rows in enumerate(batch.slices()):
        share = (rows.stop - rows.start) / total
        part = split_result(result, rows)
        out.append((*score(models, robot, batch.part(i), label, part, evaluations * share, wall * share,
                           success_deg), part))
    return out


def broken(perception) -> set[str]:
    """The modalities this perception holds at precision 0 (a dead sensor): not observed."""
    return {name for name, pi in perception.precisions.items() if np.all(np.asarray(pi) == 0)}


def observations(perception, targets) -> dict:
    """The targets' readings of every sensor the perception observes (a dead one left out). modality → (N, *out)"""
    dead = broken(perception)
    return targets.tensors([m.modality for m in perception.models if m.modality not in dead])
