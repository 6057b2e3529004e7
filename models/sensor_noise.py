"""A sensor's own noise added to a model's uncertainty: the precision of the sensory prediction error.

    Π(z) = 1 / (σ² + 1/Π_model(z))

A model fitted to noise-free simulation reports only its own uncertainty: a GP on exact kinematics claims
Π_model ≈ 1e9 m⁻² near its training poses and less between them. Taken as the sensor's precision, the −½ ln|Π(z)|
term of F then pulls the belief toward the training poses (measured on nao_arm ee_xyz, GPR of 800 points, level 1:
9.9° and 12.7 mm of ee error with the GP's own Π, 0.69° and 0.002 mm with a 1 mm sensor). A real sensor's noise σ
bounds Π by 1/σ², and the model's uncertainty still counts wherever it is the larger.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import torch

from bodyschema.errors import must_be


class NoisySensor:
    """`model` with Π = 1/(σ² + 1/Π_model): everything else (predict, jacobian, vjp, body, …) is the model's."""

    def __init__(self, model, sigma: float):
        if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma >= 0):
            raise ValueError(must_be(f"sensor noise of {model.modality!r}", "a finite σ ≥ 0 in the output's unit",
                                     sigma))
        self.model, self.sigma = model, float(sigma)

    def __getattr__(self, name):
        if name == "model":                    # not set yet (copy, unpickling): no recursion through __getattr__
            raise AttributeError(name)
        return getattr(self.model, name)

    def precision(self, z: torch.Tensor) -> torch.Tensor:
        pi = self.model.precision(z)                                       # (B, *out)
        return pi / (1.0 + self.sigma ** 2 * pi)

    def precision_vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """(∂Π/∂z)ᵀ v through Π = h(Π_model), h' = 1/(1 + σ²Π_model)². (B, Dz), (B, *out) → (B, Dz)"""
        pi = self.model.precision(z)
        return self.model.precision_vjp(z, v * (1.0 + self.sigma ** 2 * pi).pow(-2))

    def __repr__(self) -> str:
        return f"NoisySensor({self.model!r}, sigma={self.sigma:g})"


def with_sensor_noise(models: Sequence, sigmas: Mapping[str, float]) -> list:
    """`models` with each modality in `sigmas` given its sensor's noise σ (a model wrapped already is re-wrapped
    from its base, so applying this twice adds σ² once)."""
    known = {m.modality for m in models}
    unknown = sorted(set(sigmas) - known)
    if unknown:
        raise ValueError(must_be("sensor noise modality", f"one of the models' modalities {sorted(known)}", unknown))
    out = []
    for m in models:
        base = m.model if isinstance(m, NoisySensor) else m
        out.append(NoisySensor(base, sigmas[m.modality]) if m.modality in sigmas else m)
    return out
