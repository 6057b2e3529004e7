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


class ToyBlobImage(BaseSensoryModel):
    """A 16×16 'image' of a Gaussian blob at the arm's end effector: a large output, so aif takes the VJP path.
    Counts its vjp and jacobian calls."""

    kind = "toy_blob"
    SIZE, SPREAD_M, HALF_WIDTH_M = 16, 0.08, 0.6

    def __init__(self, precision: float = 100.0):
        self.arm = ToyPlanarArm()
        super().__init__(self.arm.body, "image", (self.SIZE, self.SIZE))
        self.fixed_precision = precision
        axis = torch.linspace(-self.HALF_WIDTH_M, self.HALF_WIDTH_M, self.SIZE, dtype=torch.float64)
        self.gy, self.gx = torch.meshgrid(axis, axis, indexing="ij")          # (H, W) m
        self.calls = {"vjp": 0, "jacobian": 0}

    def _blob(self, z):
        ee = self.arm._predict(z)                                          # (B, 3)
        dx = self.gx.to(z.dtype) - ee[:, 0, None, None]                    # (B, H, W)
        dy = self.gy.to(z.dtype) - ee[:, 1, None, None]
        return torch.exp(-(dx ** 2 + dy ** 2) / (2 * self.SPREAD_M ** 2)), dx, dy

    def _predict(self, z):
        return self._blob(z)[0]

    def _d_image_d_xy(self, z):
        img, dx, dy = self._blob(z)
        return torch.stack([img * dx, img * dy], -1) / self.SPREAD_M ** 2   # (B, H, W, 2)

    def _jacobian(self, z):
        self.calls["jacobian"] += 1
        d = self._d_image_d_xy(z).reshape(z.shape[0], -1, 2)               # (B, O, 2)
        return d @ self.arm._jacobian(z)[:, :2]                            # (B, O, Dz)

    def _vjp(self, z, v):
        self.calls["vjp"] += 1
        dxy = torch.einsum("bhwk,bhw->bk", self._d_image_d_xy(z), v.to(z.dtype))   # (B, 2)
        return torch.einsum("bk,bkd->bd", dxy, self.arm._jacobian(z)[:, :2])

    def _precision(self, z):
        return torch.full((z.shape[0], self.SIZE, self.SIZE), self.fixed_precision, dtype=z.dtype)
