"""The pixel decoder under the shared contract on tiny blob images, plus its training and its layout."""

import pytest
import torch

from bodyschema.models.pixel import PixelDecoder
from tests.models.contract import SensoryModelContract
from tests.toy_models import ToyPlanarArm

TINY = dict(fc_hidden=16, channels=(8, 4), epochs=15, batch_size=32, lr=1e-2, patience=100)
HW = (8, 12)


def blob_images(q: torch.Tensor, shape=HW, width_px: float = 1.5) -> torch.Tensor:
    """A camera over the toy arm: a Gaussian blob at its end effector. q (N, 2) rad → (N, *shape) in [0, 1]."""
    h, w = shape[:2]
    ee = ToyPlanarArm().predict(q.double())[:, :2]                      # (N, 2) m, inside ±0.55 m
    row = (0.5 - ee[:, 1] / 1.2) * (h - 1)                              # (N,) px
    col = (0.5 + ee[:, 0] / 1.2) * (w - 1)
    rr, cc = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    d2 = (rr - row[:, None, None]) ** 2 + (cc - col[:, None, None]) ** 2   # (N, H, W)
    img = torch.exp(-d2 / (2 * width_px ** 2))
    if len(shape) == 3:
        img = torch.stack([img * (c + 1) / shape[2] for c in range(shape[2])], -1)   # (N, H, W, C)
    return img.float()


def joint_angles(n: int, seed: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return (torch.rand(n, 2, generator=gen, dtype=torch.float64) * 4 - 2).float()   # (n, 2) rad


def tiny_decoder(shape=HW, **overrides) -> PixelDecoder:
    return PixelDecoder(ToyPlanarArm().body, "image", shape, **{**TINY, **overrides})


class TestPixelDecoder(SensoryModelContract):
    batch = 4

    def make_model(self, seed):
        q = joint_angles(128, seed=0)
        return tiny_decoder().fit(q, blob_images(q), seed=seed, progress=False)

    def make_inputs(self, n, dtype=torch.float64):
        return joint_angles(n, seed=100 + n).to(dtype)

    def make_unfitted_model(self):
        return tiny_decoder()
