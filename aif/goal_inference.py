"""Goal inference: the pose at which a goal would be perceived, found in imagination before the arm moves.

A goal x_d in a sense (an image, an ee position, a pixel plus a depth cue) is taken as an imagined observation,
and the perception that estimates the arm's pose from its senses estimates the pose that would produce it:

    q_d = argmin_q F(q; x_d),   F = Σ_goals ½ (x_d − g(q))ᵀ Π (x_d − g(q)) − ½ ln|Π|

with the same models, update and precisions as perception proper. The controller then attracts the belief to q_d
in joint space (the attractor of the joints model, f = Π_d (q_d − μ)). Why: the goal's own attractor descends
|x_d − g(μ)|² from the current belief while the arm moves, and stops in that descent's local minima (a 7-DOF arm
against its joint limits, an image goal that hardly overlaps the arm's current image); an imagined search from
several starts leaves them before any movement. The PD baseline is handed the target's true inverse kinematics;
this is the robot's own inverse model, its forward models inverted by inference.

Starts: the current belief, the caller's guesses (an image encoder's estimate) and random poses; every start runs
to convergence. Of the poses whose F is within `margin` nats of the lowest, the one nearest the current belief wins
(least joint travel): a redundant arm has many exact solutions of an ee goal, and the nearest is the one to move to.

An image goal runs its starts one after another, each over all B goals, so a progress bar counts them (when
asked): imagining 100 image goals from 8 starts takes minutes, and eight calls of 100 images took 0.5–0.8× the time
of one call of 800 (predict + vjp of a 56×80 decoder, side by side). Other goals run every start in one batch (its
bar shows the seconds only): one batch took 1/2 the time of eight with analytic ee_xyz models (100 goals × 8 starts)
and 1/7 with an 800-point GP (20 goals × 8 starts), whose cost is per call more than per row.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import torch
from tqdm.auto import tqdm

from bodyschema import log
from bodyschema.aif.free_energy import model_input, sensory_terms
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import is_image
from bodyschema.aif.precisions import perceived_precisions
from bodyschema.errors import must_be


@dataclass
class GoalPose:
    q: torch.Tensor             # (B, Dz) rad, the imagined pose of every goal
    F: torch.Tensor             # (B,) its free energy (inf where every start diverged)
    chosen: torch.Tensor        # (B,) the start it came from: 0 = the current belief, then the guesses
    evaluations: int            # model evaluations over every start


def infer_goal_pose(perception: Perception, goal: Mapping[str, torch.Tensor], belief: torch.Tensor,
                    guesses: torch.Tensor | None = None, margin: float = 1.0, progress: bool = False) -> GoalPose:
    """perception: over the goal's modalities (their precisions are the goal's); goal: modality → (B, *out);
    belief: (B, Dz) rad; guesses: (B, S, Dz) rad further starts, or None; margin: nats of F within the best;
    progress: a bar (over the starts of an image goal)."""
    dz = perception.latent_dim
    if not isinstance(belief, torch.Tensor) or belief.ndim != 2 or belief.shape[1] != dz:
        got = tuple(belief.shape) if isinstance(belief, torch.Tensor) else type(belief).__name__
        raise ValueError(must_be("belief", f"a tensor of shape (B, {dz}) rad", got))
    b = belief.shape[0]
    if guesses is None:
        guesses = belief.new_zeros(b, 0, dz)
    if not isinstance(guesses, torch.Tensor) or guesses.ndim != 3 or guesses.shape[::2] != (b, dz):
        got = tuple(guesses.shape) if isinstance(guesses, torch.Tensor) else type(guesses).__name__
        raise ValueError(must_be("guesses", f"a tensor of shape ({b}, S, {dz}) rad", got))
    if not margin >= 0:
        raise ValueError(must_be("margin", "≥ 0 nats", margin))
    starts = torch.cat([belief[:, None].to(torch.float64), guesses.to(torch.float64)], dim=1)   # (B, S, Dz)
    mu, free, evaluations = _search(perception, goal, starts, progress)
    good = free <= free.min(dim=1, keepdim=True).values + margin           # (B, S) as good as the best
    travel = (mu - belief[:, None]).abs().sum(-1)                          # (B, S) rad from the belief
    chosen = torch.where(good, travel, torch.inf).argmin(dim=1)            # (B,) the nearest good one
    picked = torch.arange(b)
    return GoalPose(mu[picked, chosen], free[picked, chosen], chosen, evaluations)


def _search(perception: Perception, goal: Mapping[str, torch.Tensor], starts: torch.Tensor,
            progress: bool) -> tuple[torch.Tensor, torch.Tensor, int]:
    """Perception of every goal from every start → (mu (B, S, Dz) rad, F (B, S), inf where diverged; evaluations).
    An image goal: one start at a time (module doc); else all B·S in one batch."""
    b, s, dz = starts.shape
    if not any(map(is_image, goal)):
        tiled = {name: x.repeat_interleave(s, dim=0) for name, x in goal.items()}
        with log.phase(f"imagining {b} goals from {s} starts", progress):
            result = perception.infer(tiled, starts.reshape(b * s, dz))
        free = torch.where(result.diverged, torch.inf, result.F)
        return result.mu.reshape(b, s, dz), free.reshape(b, s), result.evaluations
    results = [perception.infer(goal, starts[:, k])
               for k in tqdm(range(s), desc=f"imagining {b} goals", unit="start", disable=not progress, leave=False)]
    mu = torch.stack([r.mu for r in results], dim=1)                                           # (B, S, Dz)
    free = torch.stack([torch.where(r.diverged, torch.inf, r.F) for r in results], dim=1)      # (B, S)
    return mu, free, sum(r.evaluations for r in results)


def goal_precision(models, mu: torch.Tensor, gain: float,
                   precisions: Mapping[str, float] | None = None) -> float:
    """Π of a joint-space goal that outweighs every sense by `gain`: gain × the median over the batch of the mean
    diagonal of Σ_m J_mᵀ Π_m J_m at beliefs mu (B, Dz) rad (the senses' information about the joints, each
    model's as perception sees it, aif/precisions.py). A goal weaker than the senses cannot lead the belief, and
    action follows the belief: an image sense (JᵀΠJ ~ 1e6–1e7 rad⁻² per joint) would hold it where the arm is."""
    mu, overrides = mu.to(torch.float64), perceived_precisions(models, precisions)   # perception's rule
    live = [m for m in models if overrides.get(m.modality) != 0]              # a broken sense informs nothing
    given = {m.modality: torch.full((len(mu), *m.output_shape), float(overrides[m.modality]), dtype=torch.float64)
             for m in live if m.modality in overrides}
    at_mu = {m.modality: m.predict(model_input(m, mu)).detach().to(torch.float64) for m in live}
    terms = sensory_terms(live, at_mu, given, mu, need_hessian=True, need_grad=False)
    information = torch.diagonal(terms.hessian, dim1=1, dim2=2).mean(-1)   # (B,) rad⁻²
    return gain * float(information.median())
