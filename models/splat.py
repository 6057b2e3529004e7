"""The kinematic splat decoder: the network of `PixelDecoder(size="splat")`, u → image as blobs moved by the joints.

A point fixed on any link of a revolute chain is, in the base frame, a polynomial of degree one in every joint's
(1, cos q_d, sin q_d): a linear function of the 3^D products φ(q) (the GP's kinematic kernel holds ee_xyz exactly
in them, `_gp_trig.py`). Its pixel is that point over its depth, so each of K blobs has its image position
(a·φ, b·φ) / (1 + c·φ) by one linear layer φ → 3K, a width, and an intensity per channel; the image is a learned
background plus the sum of the blobs (separable Gaussians: a blob costs H + W, the sum one batched matrix product).
The structure is what the conv decoders lack on an arm they were not tuned for: the arm covers 1–4 % of a
frame that shows its whole reach, and a stack of transposed convolutions has to learn from a few thousand images
where a thin link lies for every pose (floors of 10–160° per joint on the SO-101 at 3 000 images, README), while
here where a blob lies follows the kinematics by construction and only ~100k weights are learned.
Limits: at most 7 joints (3^7 = 2 187 features per blob, as the kinematic kernel); blobs are round, so an image
is a blurred arm (fine shape is left to the conv sizes); joints must be revolute (a prismatic one is not a
polynomial of cos/sin: its blobs are then only approximately placed).
The Jacobian is written out in forward mode: per joint, the blobs' position tangents through the Gaussians, all
joints in one batched matrix product.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from bodyschema.models._gp_trig import MAX_FEATURES, feature_count, features, features_and_derivatives
from bodyschema.models._nn_fit import LeafParams
from bodyschema.models.scaling import BodySpec

DEPTH_SHARPNESS = 5.0     # softplus(β = 5) keeps the depth 1 + c·φ positive, ≈ identity above 0.5
# Blobs learn to leave the image at some poses by a depth near 0 (their position over it far outside): on SO-101's
# 15 000-image store 1 % of (pose, blob) depths were under 6e-9, the least 5e-20, and position / depth² overflowed
# float32 in its 30th epoch (NaN weights from there). Floored here, such a blob is still 1000× its position away.
DEPTH_MIN = 1e-3
FOREGROUND = 0.1          # an intensity this far from the background's marks the arm, where blobs start
START_WIDTH_PX = 2.5      # a blob's starting σ in pixels
START_INTENSITY = 0.3     # each blob's starting intensity (start_from says why)


class SplatNet(nn.Module):
    """u (B, Dz) in [-1, 1] → image (B, *output_shape), K blobs placed by the trig features of q = from_unit(u)."""

    def __init__(self, body: BodySpec, output_shape: tuple[int, ...], points: int, channels: int):
        super().__init__()
        self.output_shape, self.k, self.c = tuple(output_shape), points, channels
        self.h, self.w = self.output_shape[:2]
        self.body = body                                                         # u ↔ q: its from_unit
        self.place = nn.Linear(feature_count(body.latent_dim), 3 * points)      # φ → (a·φ, b·φ, c·φ) per blob
        self.look = LeafParams(log_width=(points,), intensity=(points, channels), background=(channels, self.h, self.w))

    @torch.no_grad()
    def start_from(self, x: torch.Tensor, gen: torch.Generator) -> None:
        """Background = the per-pixel median of the training images x (N, *output_shape) in [0, 1] (the arm covers
        a pixel in under half of them); blobs start still, at pixels where an image differs from it."""
        x = x.reshape(x.shape[0], self.h, self.w, self.c)
        background = x[:1000].median(0).values                                  # (H, W, C)
        self.look.background.copy_(background.permute(2, 0, 1))
        arm = ((x[:1000] - background).abs().amax(-1) > FOREGROUND).nonzero()  # (M, 3): image, row, col
        found = len(arm) > 0
        if not found:                                                            # a blank store: anywhere
            arm = torch.cartesian_prod(torch.zeros(1, dtype=torch.long), torch.arange(self.h), torch.arange(self.w))
        pick = arm[torch.randint(len(arm), (self.k,), generator=gen)]
        self.place.weight.normal_(0, 1e-3, generator=gen)
        start = self.place.bias.view(self.k, 3)
        start[:, 0] = _unit_grid(self.w, start)[pick[:, 2]]
        start[:, 1] = _unit_grid(self.h, start)[pick[:, 1]]
        start[:, 2] = 0.0
        self.look.log_width.fill_(math.log(START_WIDTH_PX * 2 / max(self.h, self.w)))
        # 0.3: strong position gradients from the first step (∂image/∂position ∝ intensity). Blobs that start with
        # the arm's mean mass (~0.02 each) fit every held-out image better but moved less: floors better on
        # nao_arm, worse on four foreign arms (issue 33's closing note). A store with no arm in view starts blank.
        self.look.intensity.fill_(START_INTENSITY if found else 0.0)

    def _blobs(self, raw: torch.Tensor):
        """raw (B, K, 3) → depth (B, K), the offsets of every column/row from each blob (B, K, W), (B, K, H) in
        unit image coordinates, 1/(2σ²) (K,), and the separable Gaussians (B, K, W), (B, K, H)."""
        depth = F.softplus(1 + raw[..., 2], beta=DEPTH_SHARPNESS).clamp_min(DEPTH_MIN)
        inv = torch.exp(-2 * self.look.log_width) / 2
        dx = _unit_grid(self.w, raw) - (raw[..., 0] / depth)[..., None]
        dy = _unit_grid(self.h, raw) - (raw[..., 1] / depth)[..., None]
        return depth, dx, dy, inv, torch.exp(-dx ** 2 * inv[:, None]), torch.exp(-dy ** 2 * inv[:, None])

    def _image(self, gx: torch.Tensor, gy: torch.Tensor) -> torch.Tensor:
        """Σ_k intensity_k gy_k ⊗ gx_k + background → (B, *output_shape)."""
        img = torch.stack([torch.bmm(gy.transpose(1, 2) * a, gx) for a in self.look.intensity.T], 1)   # (B, C, H, W)
        return (img + self.look.background).permute(0, 2, 3, 1).reshape(-1, *self.output_shape)

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        raw = self.place(features(self.body.from_unit(u))).view(-1, self.k, 3)
        *_, gx, gy = self._blobs(raw)
        return self._image(gx, gy)

    def forward_and_jacobian(self, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """g(u) and ∂g/∂u. # u (B, Dz) → (B, *output_shape), (B, O, Dz), O in (H, W, C) order"""
        b, dz = u.shape
        phi, dphi = features_and_derivatives(self.body.from_unit(u))       # (B, P), (B, Dz, P) per rad
        dphi = dphi / self.body.unit_per_rad(u)[:, None]                   # per unit of u
        raw = self.place(phi).view(b, self.k, 3)
        draw = (dphi @ self.place.weight.T).view(b, dz, self.k, 3)         # the bias moves no tangent
        depth, dx, dy, inv, gx, gy = self._blobs(raw)
        slope = torch.sigmoid(DEPTH_SHARPNESS * (1 + raw[..., 2])) * (depth > DEPTH_MIN)   # softplus'; 0 at the floor
        ddepth = slope[:, None] * draw[..., 2]                                              # · dc·φ
        dpx = draw[..., 0] / depth[:, None] - (raw[..., 0] / depth ** 2)[:, None] * ddepth     # (B, Dz, K)
        dpy = draw[..., 1] / depth[:, None] - (raw[..., 1] / depth ** 2)[:, None] * ddepth
        gx_slope = (gx * dx * 2 * inv[:, None])[:, None]                   # ∂gx/∂px (B, 1, K, W)
        gy_slope = (gy * dy * 2 * inv[:, None])[:, None]
        per_channel = []
        for a in self.look.intensity.T:          # d(gy ⊗ gx) = dgy ⊗ gx + gy ⊗ dgx: both in one product
            left = torch.cat([gy_slope * (a[:, None] * dpy[..., None]),
                              (gy * a[:, None])[:, None].expand(b, dz, -1, -1)], 2)        # (B, Dz, 2K, H)
            right = torch.cat([gx[:, None].expand(b, dz, -1, -1), gx_slope * dpx[..., None]], 2)   # (B, Dz, 2K, W)
            per_channel.append(left.transpose(2, 3) @ right)               # (B, Dz, H, W)
        jac = torch.stack(per_channel, -1).reshape(b, dz, -1).transpose(1, 2)   # (B, H·W·C, Dz)
        return self._image(gx, gy), jac


def fits(latent_dim: int) -> bool:
    return feature_count(latent_dim) <= MAX_FEATURES


def _unit_grid(n: int, like: torch.Tensor) -> torch.Tensor:
    """Pixel centres across one image side in [-1, 1], of like's dtype and device."""
    return torch.linspace(-1.0, 1.0, n, dtype=like.dtype, device=like.device)
