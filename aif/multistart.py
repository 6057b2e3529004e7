"""Multi-start perception: S beliefs per trial, screened briefly, the lowest-F ones refined to convergence.

The remedy for level 3 (a belief that starts at an unrelated pose may fall into another basin of F): run all
B·S starts for `screen_steps` updates in one batch, prune every trial to its `keep` starts of lowest F, run
those to convergence, and return per trial the one of lowest final F. Where the model cannot tell two poses
apart (equal F, e.g. elbow-up and elbow-down under an end-effector sensor), no start selection can either.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import torch

from bodyschema.aif.perception import Perception, PerceptionResult
from bodyschema.errors import must_be


@dataclass
class MultiStartResult:
    result: PerceptionResult       # of the chosen start per trial (steps: screening + refinement)
    chosen: torch.Tensor           # (B,) index of the chosen start in 0..S−1
    screen_F: torch.Tensor         # (B, S) free energy after screening
    evaluations: int               # model evaluations, screening + refinement, summed over trials


def infer_multistart(perception: Perception, observations: Mapping[str, torch.Tensor], starts: torch.Tensor,
                     screen_steps: int = 20, keep: int = 1) -> MultiStartResult:
    """starts: (B, S, Dz) rad, e.g. draws from the robot's sampling distribution plus the usual initial belief."""
    if not isinstance(starts, torch.Tensor) or starts.ndim != 3 or starts.shape[-1] != perception.latent_dim:
        got = tuple(starts.shape) if isinstance(starts, torch.Tensor) else type(starts).__name__
        raise ValueError(must_be("starts", f"a tensor of shape (B, S, {perception.latent_dim}) rad", got))
    b, s, dz = starts.shape
    if not 1 <= keep <= s:
        raise ValueError(must_be("keep", f"between 1 and S = {s}", keep))
    if screen_steps < 1:
        raise ValueError(must_be("screen_steps", "at least 1", screen_steps))
    cfg = perception.config
    screen = perception.with_config(replace(cfg, max_steps=screen_steps, record=False))
    tiled = {name: x.repeat_interleave(s, dim=0) for name, x in observations.items()}
    first = screen.infer(tiled, starts.reshape(b * s, dz))                 # (B·S) trials
    screen_F = torch.where(first.diverged, torch.inf, first.F).reshape(b, s)
    best = screen_F.argsort(dim=1)[:, :keep]                               # (B, keep)
    rows = (torch.arange(b)[:, None] * s + best).reshape(-1)               # (B·keep,)
    refine = {name: x.repeat_interleave(keep, dim=0) for name, x in observations.items()}
    final = perception.infer(refine, first.mu_tilde[rows])
    final_F = torch.where(final.diverged, torch.inf, final.F).reshape(b, keep)
    pick = final_F.argmin(dim=1)                                           # (B,)
    idx = torch.arange(b) * keep + pick
    chosen = best[torch.arange(b), pick]
    res = final
    screened_steps = first.steps.reshape(b, s)[torch.arange(b), chosen]
    picked = PerceptionResult(res.mu[idx], res.mu_tilde[idx], screened_steps + res.steps[idx], res.converged[idx],
                              res.diverged[idx], res.diverged_step[idx], res.F[idx], 0,
                              None if res.trajectory is None else
                              {k: v[:, idx] for k, v in res.trajectory.items()})
    return MultiStartResult(picked, chosen, screen_F, first.evaluations + final.evaluations)


def lowest_free_energy(results: Sequence[PerceptionResult]) -> tuple[PerceptionResult, torch.Tensor]:
    """Per trial, the result of lowest final F among results of the same B trials from different starts (a diverged
    trial counts as F = inf), e.g. the level's own start and an encoder's guess, each run to convergence apart.
    → (the picked result, evaluations summed over all; its trajectory, if recorded, the picked start's column padded
    with NaN to the longest), (B,) index of the picked result per trial."""
    free = torch.stack([torch.where(r.diverged, torch.inf, r.F) for r in results])   # (S, B)
    chosen = free.argmin(dim=0)                                                       # (B,)
    rows = torch.arange(free.shape[1])

    def pick(name):
        return torch.stack([getattr(r, name) for r in results])[chosen, rows]

    trajectory = None
    if all(r.trajectory is not None for r in results):
        steps = max(len(r.trajectory["F"]) for r in results)
        trajectory = {name: _padded([r.trajectory[name] for r in results], steps)[chosen, :, rows].movedim(0, 1)
                      for name in results[0].trajectory}                          # (T, B, ...)
    picked = PerceptionResult(pick("mu"), pick("mu_tilde"), pick("steps"), pick("converged"), pick("diverged"),
                              pick("diverged_step"), pick("F"), sum(r.evaluations for r in results), trajectory)
    return picked, chosen


def _padded(rows: Sequence[torch.Tensor], steps: int) -> torch.Tensor:
    """Trajectories (T_s, B, ...) NaN-padded to `steps` and stacked. → (S, steps, B, ...)"""
    out = torch.full((len(rows), steps, *rows[0].shape[1:]), float("nan"), dtype=rows[0].dtype)
    for s, r in enumerate(rows):
        out[s, :len(r)] = r
    return out
