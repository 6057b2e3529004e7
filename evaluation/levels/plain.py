"""Pixel-AIF's plain perception protocol (Sancaktar et al. 2020), the reference row beside the default update:
Euler steps of Δt 0.1 on F with its visual precision 1/Σ_v, Σ_v = 2·10⁴ at levels 1–2 and 2·10³ at level 3 (the
precision ×10 once a trial's image MSE ≤ 0.01), 5000 steps, no step control. On rough real images a slow flow that
stays near a close start can beat a fast update at level 1: `evaluate levels --targets` shows both rows.

`plain_infer` runs it in chunks of Euler steps (the state is μ alone, so chunking is exact); `PlainPixelAIF` wraps it
as a perception (`.models`, `.precisions`, `.infer`) so `evaluate_level` scores it like any update. bench/aif.py
uses the same functions.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.base.modalities import IMAGE, is_image

PLAIN = PerceptionConfig(method="flow", flow=FlowSettings(integrator="euler", dt=0.1, k_z=1.0, step_control="none"),
                         max_steps=5000, tol=0.0, max_step=None, record=True)
PLAIN_STEPS = PLAIN.max_steps
PLAIN_LABEL = "plain Pixel-AIF"        # the row's label after the level number
CHUNK = 100                            # Euler steps between level-3 precision checks
MSE_SWITCH = 0.01                      # level 3: the image MSE below which Σ_v drops to the levels 1–2 value


def pixel_aif_plain(level: int) -> PerceptionConfig:
    """Pixel-AIF's own update at `level`: Euler Δt 0.1 on F with its visual precision 1/Σ_v."""
    sigma_v = 2e3 if level == 3 else 2e4
    return replace(PLAIN, precisions=((IMAGE, 1.0 / sigma_v),), record=False,
                   flow=replace(PLAIN.flow, divergence_ratio=None))


def plain_infer(models, obs, mu0, level: int, steps: int = PLAIN_STEPS, chunk: int = CHUNK):
    """The plain protocol for `steps` Euler steps from mu0 (B, Dz); steps and divergence summed over the chunks."""
    image = next(m for m in models if is_image(m.modality))
    mu, evaluations, taken, diverged = mu0.clone(), 0, torch.zeros(len(mu0), dtype=torch.long), None
    pi = torch.full((len(mu0),), dict(pixel_aif_plain(level).precisions)[IMAGE], dtype=torch.float64)
    for start in range(0, steps, chunk):
        if level == 3:
            with torch.no_grad():
                mse = (image.predict(mu.float()).double() - obs[image.modality]).pow(2).flatten(1).mean(dim=1)
            pi = torch.where(mse <= MSE_SWITCH, dict(pixel_aif_plain(2).precisions)[IMAGE], pi)
        cfg = replace(pixel_aif_plain(level), max_steps=min(chunk, steps - start), precisions=())
        res = Perception(models, cfg, {image.modality: pi.view(-1, *[1] * len(image.output_shape))
                                       .expand(-1, *image.output_shape)}).infer(obs, mu)
        mu, evaluations, taken = res.mu, evaluations + res.evaluations, taken + res.steps
        diverged = res.diverged if diverged is None else diverged | res.diverged
    res.mu, res.evaluations, res.steps, res.diverged = mu, evaluations, taken, diverged
    return res


class PlainPixelAIF:
    """The plain protocol at one level as a perception: `infer(obs, mu0)` → the result `evaluate_level` scores."""

    def __init__(self, models, level: int, steps: int = PLAIN_STEPS):
        self.models, self.level, self.steps = list(models), level, steps
        self.precisions: dict = {}

    def infer(self, obs, mu0):
        return plain_infer(self.models, obs, mu0, self.level, self.steps)
