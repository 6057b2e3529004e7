"""What a conv image decoder's first layer reads of the pose (`PixelDecoder(inputs=...)`), with its derivatives.

A point fixed on a link of a revolute chain is, in the base frame, a sum of products over the joints of an affine
function of each joint's (1, cos q_d, sin q_d) (the GP's kinematic kernel holds ee_xyz exactly in all 3^D such
products, `_gp_trig.py`), and its pixel is such a sum over another (its depth). Read through the scaled angles u
alone, the decoder's fully connected layers have to build those products out of ELUs; given them, the first layer
only has to mix them (README "What the decoder reads of the pose": lower floors on every arm measured).

- "products" (the default): R = min(PRODUCTS, 3^D) learned products Π_d a_rd · (1, cos q_d, sin q_d), each a
  rank-one term of that expansion with 3·D weights, for any number of joints, less its constant part Π_d a_rd0
  (the next layer's bias holds it): inputs centred over the joints' circles, which Adam's per-weight steps need.
  The factors start at 1 + (cos, sin)·N(0, 1/D). No more products than the 3^D terms: 256 products of a 2-joint
  arm (nine terms) sent every pose to one image within three epochs on a toy blob (their steps on nearly
  collinear inputs add up).
- "kinematic": all 3^D products, up to 7 joints. On 6–7 joints and a few thousand poses the first layer's 3^D
  weights per unit over-fit (the UR5 at 3 000 poses stopped early, its floors above u's).
- "unit": u ∈ [-1, 1]^D itself (every decoder fitted before 2026-11-30).
Each maps u (B, D) to features (B, P) and, for the Jacobian, to them and their derivatives in u (B, D, P).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from bodyschema.errors import must_be
from bodyschema.models._gp_trig import MAX_FEATURES, feature_count, features, features_and_derivatives
from bodyschema.models._nn_fit import LeafParams
from bodyschema.models.scaling import BodySpec

PRODUCTS = 256   # at most this many learned products (1024 did worse on SO-101 and the UR5: README)
INPUTS = ("unit", "products", "kinematic")
DEFAULT_INPUTS = "products"


class UnitInputs(nn.Module):
    """u itself: P = D, ∂u/∂u = I."""

    def __init__(self, joints: int):
        super().__init__()
        self.size = joints

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        return u

    def with_derivatives(self, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        eye = torch.eye(u.shape[1], dtype=u.dtype, device=u.device)
        return u, eye.expand(u.shape[0], -1, -1)


class _TrigInputs(nn.Module):
    """Features of q = from_unit(u); subclasses give them (`_values`, what ONNX exports) and with their
    derivatives per rad (`_values_and_slopes`)."""

    def __init__(self, body: BodySpec):
        super().__init__()
        self.body = body                                                   # u ↔ q

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        return self._values(self.body.from_unit(u))

    def with_derivatives(self, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        phi, per_rad = self._values_and_slopes(self.body.from_unit(u))
        return phi, per_rad / self.body.unit_per_rad(u)[:, None]          # per unit of u

    def _values(self, q: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _values_and_slopes(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        raise NotImplementedError


class KinematicInputs(_TrigInputs):
    """All 3^D products of the joints' (1, cos q_d, sin q_d)."""

    def __init__(self, body: BodySpec):
        super().__init__(body)
        self.size = feature_count(body.latent_dim)

    def _values(self, q):
        return features(q)

    def _values_and_slopes(self, q):
        return features_and_derivatives(q)


class ProductInputs(_TrigInputs):
    """R learned products over the joints of one affine form of (1, cos q_d, sin q_d) each."""

    def __init__(self, body: BodySpec, products: int = PRODUCTS):
        super().__init__(body)
        products = min(products, feature_count(body.latent_dim))    # no more than the expansion has terms
        self.size = products
        self.factors = LeafParams(weight=(products, body.latent_dim, 3))   # a_rd; set by `start`

    @torch.no_grad()
    def start(self, gen: torch.Generator) -> None:
        weight = self.factors.weight
        weight.copy_(torch.randn(weight.shape, generator=gen) / math.sqrt(weight.shape[1]))
        weight[..., 0] = 1.0

    def _factors(self, q: torch.Tensor) -> torch.Tensor:
        """a_rd · (1, cos q_d, sin q_d). q (B, D) → (B, R, D)"""
        basis = torch.stack([torch.ones_like(q), q.cos(), q.sin()], -1)   # (B, D, 3)
        return torch.einsum("bdk,rdk->brd", basis, self.factors.weight)

    def _values(self, q):
        return self._centred(self._factors(q))

    def _centred(self, factor: torch.Tensor) -> torch.Tensor:
        """Π_d factor less its constant part Π_d a_rd0. (B, R, D) → (B, R)"""
        return factor.prod(-1) - self.factors.weight[..., 0].prod(-1)

    def _values_and_slopes(self, q):
        factor = self._factors(q)                                          # (B, R, D)
        slope = torch.stack([torch.zeros_like(q), -q.sin(), q.cos()], -1)  # d(1, cos, sin)/dq_d
        factor_slope = torch.einsum("bdk,rdk->brd", slope, self.factors.weight)
        ones = torch.ones_like(factor[..., :1])
        before = torch.cat([ones, factor[..., :-1]], -1).cumprod(-1)      # Π_{e<d}: no division by a factor near 0
        after = torch.cat([factor[..., 1:], ones], -1).flip(-1).cumprod(-1).flip(-1)   # Π_{e>d}
        return self._centred(factor), (factor_slope * before * after).transpose(1, 2)   # (B, R), (B, D, R)


def check_inputs(kind: str, joints: int) -> None:
    """The house error for an unknown kind (INPUTS) or a "kinematic" one past 7 joints."""
    if kind not in INPUTS:
        raise ValueError(must_be("inputs", f"one of {INPUTS}", kind))
    if kind == "kinematic" and feature_count(joints) > MAX_FEATURES:
        raise ValueError(must_be("inputs 'kinematic'", "used on at most 7 joints (3^D features)", joints,
                                 "Use inputs 'products', which takes any number of joints."))


def pose_inputs(kind: str, body: BodySpec) -> nn.Module:
    """The module for `kind` (INPUTS) on `body`'s joints (check_inputs' errors)."""
    check_inputs(kind, body.latent_dim)
    return {"unit": lambda: UnitInputs(body.latent_dim), "products": lambda: ProductInputs(body),
            "kinematic": lambda: KinematicInputs(body)}[kind]()
