"""Sensor consistency: does any low-dimensional sensor contradict a belief, whatever F says?

F sums every sensor's precision-weighted error. An image's thousands of pixels, weighted as independent, can then
favour a wrong pose by as much as the joint encoders penalise it, so F at the wrong pose equals F at the truth
(nao_arm fused with joints: 13 frames ~10° off). Each low-dimensional sensor (joints, ee; at most
JACOBIAN_MAX_OUTPUTS outputs, so no image is evaluated again) gets its own bound on ½ εᵀΠε, calibrated at true
poses by the tracker's lost-track rule (`above_spread`) and never below the ½ χ² quantile its own precision
expects; a belief above one sensor's bound is contradicted.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import torch

from bodyschema.aif.free_energy import JACOBIAN_MAX_OUTPUTS
from bodyschema.aif.perception import Perception, as_inputs


def above_spread(values: np.ndarray, quantile: float, slack: float) -> float:
    """The lost-track rule on values at true poses: their `quantile` plus `slack` times its distance to the median."""
    top = float(np.quantile(values, quantile))
    return top + slack * (top - float(np.median(values)))


def _outputs(model) -> int:
    return math.prod(model.output_shape)


class SensorChecks:
    """The checked sensors of a perception and their bounds (empty until `calibrate`)."""

    def __init__(self, perception: Perception, precisions: Mapping | None, limits):
        small = [m for m in perception.models if _outputs(m) <= JACOBIAN_MAX_OUTPUTS]
        self.names = {m.modality for m in small}
        config = replace(perception.config, precisions=tuple((k, v) for k, v in perception.config.precisions
                                                             if k in self.names))
        self.perception = Perception(small, config, {k: v for k, v in (precisions or {}).items()
                                                     if k in self.names}, limits)
        self.bounds: dict[str, float] = {}                       # modality → ½ εᵀΠε above which it contradicts

    @classmethod
    def of(cls, perception: Perception, precisions, limits) -> SensorChecks | None:
        """Checks for a perception of several modalities with at least one low-dimensional; else None."""
        models = perception.models
        if len(models) < 2 or all(_outputs(m) > JACOBIAN_MAX_OUTPUTS for m in models):
            return None
        return cls(perception, precisions, limits)

    def calibrate(self, observations, q_true, quantile: float, slack: float) -> dict[str, float]:
        """Each sensor's bound from its ½ εᵀΠε at the true poses q_true (N, Dz) of frames `observations`. → bounds"""
        from scipy.stats import chi2
        _, errors = self.perception.energies(self._sensed(as_inputs(observations)), q_true)
        outputs = {m.modality: _outputs(m) for m in self.perception.models}
        # never below what the sensor's own precision expects at the truth, ½ εᵀΠε ~ ½ χ²(outputs): frames with less
        # noise than their precision says would otherwise leave no room at all
        self.bounds = {name: max(above_spread(e.numpy(), quantile, slack),
                                 0.5 * float(chi2.ppf(quantile, outputs[name])))
                       for name, e in errors.items() if name in outputs}
        return self.bounds

    def contradicted(self, observations, mu: torch.Tensor | None) -> torch.Tensor:
        """(B,) bool: a sensor's ½ εᵀΠε at beliefs mu (B, Dz) above its bound; all False before `calibrate` or for
        no belief yet (the tracker's first frame restarts anyway)."""
        b = next(iter(observations.values())).shape[0]
        out = torch.zeros(b, dtype=torch.bool)
        if not self.bounds or mu is None:
            return out
        _, errors = self.perception.energies(self._sensed(observations), mu)
        for name, bound in self.bounds.items():
            if name in errors:                                   # a broken sensor (Π = 0) has no term
                out |= ~(errors[name] <= bound)
        return out

    def _sensed(self, observations: Mapping) -> dict:
        return {name: x for name, x in observations.items() if name in self.names}
