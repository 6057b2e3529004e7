"""Benchmark: does a decoder size train on a store's images, or stall at the mean image? (issue 33, item 4)

Trains each `--sizes` preset (models/pixel.py SIZES; `size:{'lr': 5e-4}` overrides keywords) on the first `--n`
training images of one store, validation on its split (seed 0), and prints per epoch the held-out loss per pixel
(the size's `loss`), then for the kept weights: the held-out MSE (intensity in [0, 1]) beside the mean training
image's (the plateau a decoder that ignores the pose sits on), how much the prediction varies with the pose
(mean over pixels of the std across held-out poses, vs the images' own), the share of the second fully connected
layer's units below -2 (ELU saturated: a gradient under e⁻² of the unit's), the brightest predicted pixel (near 0:
the sigmoid saturated on a black image, σ' ≈ 0, from which no gradient brings it back), and the pose variation at init.
Small by default (a shared 2-core machine): `--n 600 --epochs 8`, 64×64 nao_arm ≈ 1 min lean, ≈ 7 min pixel_aif.
Run: `MUJOCO_GL=egl .venv/bin/bodyschema datagen --robot nao_arm --n 1200 --image-size 64 64 --out /tmp/nao64.zarr`
then `.venv/bin/python bench/decoder_rule.py --data /tmp/nao64.zarr --sizes lean pixel_aif`.
"""

from __future__ import annotations

import argparse
import ast
import time

import torch

from bodyschema.models._nn_fit import build
from bodyschema.models.pixel import PixelDecoder
from bodyschema.training.data import as_float, load_dataset


def pose_variation(net, u: torch.Tensor) -> float:
    """Mean over pixels of the prediction's std across the poses u (B, Dz)."""
    with torch.no_grad():
        return float(net(u).std(0).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--sizes", nargs="+", default=["lean", "pixel_aif"])
    ap.add_argument("--n", type=int, default=600)
    ap.add_argument("--epochs", type=int, default=8)
    args = ap.parse_args()
    data = load_dataset(args.data, ("image",), val_fraction=0.2, seed=0)
    x_train, x_val = as_float(data.train.x[:args.n]), as_float(data.val.x)   # [0, 1]
    mean_mse = float((x_val - x_train.mean(0)).pow(2).mean())
    print(f"{args.data}: image {data.output_shape('image')}, {len(x_train)} train / {len(x_val)} held-out images; "
          f"held-out MSE of the mean training image {mean_mse:.4g}; image std across poses "
          f"{float(x_val.std(0).mean()):.4f}", flush=True)
    for spec in args.sizes:
        fit_one(spec, data, args.n, args.epochs, mean_mse)


def fit_one(spec: str, data, n: int, epochs: int, mean_mse: float) -> None:
    """Train the size `spec` ("name" or "name:{keyword: value}") and print its epochs and its diagnosis."""
    size, _, kw = spec.partition(":")
    model = PixelDecoder(data.body, "image", data.output_shape("image"), size=size, epochs=epochs, patience=epochs,
                         **(ast.literal_eval(kw) if kw else {}))
    u_val = model.body.to_unit(as_float(data.val.q))                                   # (B, Dz) in [-1, 1]
    at_init = pose_variation(build(model._factory, torch.Generator().manual_seed(0)), u_val)
    losses, start = [], time.perf_counter()

    def on_epoch(epoch: int, metrics: dict) -> None:
        losses.append(metrics["val_loss"])
        print(f"  {spec} epoch {epoch + 1}: held-out {model.loss} {metrics['val_loss']:.4g}", flush=True)

    model.fit(data.train.q[:n], data.train.x[:n], val=(data.val.q, data.val.x), on_epoch=on_epoch)
    with torch.no_grad():
        saturated = float((model.net_.fc[:3](u_val) < -2).float().mean())
        predicted = model.net_(u_val)
        brightest, mse = float(predicted.max()), float((predicted - as_float(data.val.x)).pow(2).mean())
    params = sum(p.numel() for p in model.net_.parameters())
    print(f"{spec}: {params} params, held-out MSE {mse:.4g} ({mse / mean_mse:.2f}× the mean "
          f"image's), pose variation {pose_variation(model.net_, u_val):.4f} (at init {at_init:.4f}), fc units "
          f"saturated {saturated:.0%}, brightest predicted pixel {brightest:.3g}, "
          f"{time.perf_counter() - start:.0f} s", flush=True)

if __name__ == "__main__":
    main()
