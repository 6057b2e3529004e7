"""A closed-form 2-link planar arm as a SensoryModel: a fast, exact `g` for testing consumers of the contract."""

from __future__ import annotations

import torch

from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.scaling import BodySpec

LINKS_M = (0.3, 0.25)   # link lengths, m


@register_kind
class ToyPlanarArm(BaseSensoryModel):
    """ee_xyz (x, y, 0) of a planar 2-link arm; precision fixed."""

    kind = "toy_planar"

    def __init__(self, precision: float = 1e4):
        body = BodySpec("toy_planar", ("shoulder", "elbow"), (-2.5, -2.5), (2.5, 2.5))
        super().__init__(body, "ee_xyz", (3,))
        self.fixed_precision = precision

    def _predict(self, z):
        l1, l2 = LINKS_M
        a, b = z[:, 0], z[:, 0] + z[:, 1]
        return torch.stack([l1 * a.cos() + l2 * b.cos(), l1 * a.sin() + l2 * b.sin(), torch.zeros_like(a)], -1)

    def _jacobian(self, z):
        l1, l2 = LINKS_M
        a, b = z[:, 0], z[:, 0] + z[:, 1]
        zero = torch.zeros_like(a)
        row_x = torch.stack([-l1 * a.sin() - l2 * b.sin(), -l2 * b.sin()], -1)
        row_y = torch.stack([l1 * a.cos() + l2 * b.cos(), l2 * b.cos()], -1)
        return torch.stack([row_x, row_y, torch.stack([zero, zero], -1)], 1)   # (B, 3, 2)

    def _precision(self, z):
        return torch.full((z.shape[0], 3), self.fixed_precision, dtype=z.dtype)

    def _config(self):
        return {"precision": self.fixed_precision}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        return cls(config["precision"])
