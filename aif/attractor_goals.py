"""The attractor prior's goals in perception (aif/perception.py): checked once per run, and an image goal fused with
its own sensor's term at order 0, so that it costs no model call of its own."""

from __future__ import annotations

from collections.abc import Mapping

import torch

from bodyschema.aif.free_energy import JACOBIAN_MAX_OUTPUTS, model_input
from bodyschema.aif.perception_config import PerceptionConfig
from bodyschema.errors import must_be


def checked_goals(models, goal, b: int, config: PerceptionConfig) -> list[tuple[object, torch.Tensor, float]]:
    """The attractor prior's goals, checked: modality → (B, *out) target x_d of one of the models. → (model, x_d
    float64, Π_goal) per goal, Π_goal from config.goal_precisions, else config.attractor_gain."""
    if not isinstance(goal, Mapping) or len(goal) < 1:
        raise ValueError(must_be("goal", "a dict modality → (B, *out) target", goal,
                                 "The attractor prior needs a goal x_d."))
    gains = dict(config.goal_precisions)
    out = []
    for name, x_d in goal.items():
        model = next((m for m in models if m.modality == name), None)
        if model is None or not isinstance(x_d, torch.Tensor) or tuple(x_d.shape) != (b, *model.output_shape):
            raise ValueError(must_be("goal", "one of the models' modalities with a (B, *out) tensor",
                                     {name: tuple(getattr(x_d, "shape", ()))}))
        out.append((model, x_d.to(torch.float64), float(gains.get(name, config.attractor_gain))))
    return out


def fuse_image_goals(goals, rows, mu: torch.Tensor, obs: dict, pis: dict, prior_precision: float):
    """Order 0, an image goal whose model is also observed: the attractor's Π_z V = ½ β |x_d − g|² (β = Π_z · its
    Π_goal) and the sensory ½ |x − g|²_Π are one Gaussian term ½ |x̄ − g|²_(Π+β), x̄ = (Π x + β x_d)/(Π + β), up
    to a constant in μ. Fused, the goal costs no model call: its gradient and Gauss–Newton curvature come with the
    sensor's (priors.py: image goals never build their own Jacobian). Rewrites obs/pis in place.
    → the goals left to the prior (None if there were none) and the constant (b,) to add to F."""
    offset = torch.zeros(len(rows), dtype=mu.dtype)
    if goals is None:
        return None, offset
    left = []
    for model, x_d, gain in goals:
        name = model.modality
        if x_d[0].numel() <= JACOBIAN_MAX_OUTPUTS or name not in obs or getattr(model, "precision_varies", False):
            left.append((model, x_d, gain))
            continue
        b = len(rows)
        pi = pis[name] if pis[name] is not None else model.precision(model_input(model, mu)).to(mu.dtype)  # (b, *out)
        beta = torch.as_tensor(gain * prior_precision, dtype=mu.dtype)
        x, goal = obs[name].to(mu.dtype), x_d[rows].to(mu.dtype)
        total = pi + beta
        obs[name], pis[name] = (pi * x + beta * goal) / total, total
        constant = 0.5 * (pi * beta / total * (x - goal).pow(2)).reshape(b, -1).sum(-1)
        logdet = 0.5 * (torch.log(total) - torch.where(pi > 0, pi.clamp_min(1e-300).log(), 0.0)).reshape(b, -1).sum(-1)
        offset = offset + constant + logdet                                # F_x(Π) + Π_z V = F_fused + this
    return left, offset
