"""Test doubles for aif: a joint-angle sensor over the toy planar arm's body, and a model of another robot."""

from __future__ import annotations

import torch

from bodyschema.models.contract import BaseSensoryModel
from bodyschema.models.scaling import BodySpec
from tests.toy_models import ToyPlanarArm


class ToyJoints(BaseSensoryModel):
    """x = z (rad): a joint encoder with fixed precision, over the same body as ToyPlanarArm."""

    kind = "toy_joints"

    def __init__(self, precision: float = 1e3, body: BodySpec | None = None):
        super().__init__(body or ToyPlanarArm().body, "joints", (2,))
        self.fixed_precision = precision

    def _predict(self, z):
        return z.clone()

    def _jacobian(self, z):
        return torch.eye(2, dtype=z.dtype).expand(z.shape[0], 2, 2).clone()

    def _precision(self, z):
        return torch.full((z.shape[0], 2), self.fixed_precision, dtype=z.dtype)


def other_robot_joints() -> ToyJoints:
    return ToyJoints(body=BodySpec("other_robot", ("shoulder", "elbow"), (-2.5, -2.5), (2.5, 2.5)))


def planar_poses(n: int, seed: int) -> torch.Tensor:
    """Poses away from the arm's singularity (elbow bent 0.3–1.1 rad). # (n, 2) rad"""
    g = torch.Generator().manual_seed(seed)
    q = (torch.rand(n, 2, generator=g, dtype=torch.float64) * 2 - 1) * 1.5
    q[:, 1] = q[:, 1].abs() * 0.8 + 0.3
    return q


def perturb(q: torch.Tensor, seed: int, max_rad: float = 0.17) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return q + (torch.rand(q.shape, generator=g, dtype=q.dtype) * 2 - 1) * max_rad
