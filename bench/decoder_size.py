"""Benchmark: the pixel decoder's capacities ("lean" vs "pixel_aif") side by side on one image dataset.

Both sizes are trained in this run on the same store and split (`training.data.load_dataset`, seed 0), then:
  * parameters, training seconds per epoch (median), held-out MSE per pixel (intensity in [0, 1]) and that MSE
    relative to predicting the mean validation image;
  * µs per sample of one batched `vjp` at batch 500 and of `predict_and_vjp` (what an AIF step needs), float32;
  * the start-at-truth floor: perception (`PerceptionConfig(step_control="descent")`) started at the *true*
    pose of `--floor` held-out images. A perfect decoder would stay there; the mean |joint error| (deg) it
    drifts to is the error the decoder alone imposes on image-only perception.
Ratios are pixel_aif / lean. Times are the minimum over repeats (the least disturbed run on a shared machine).
The defaults finish in ~10 min on 2 cores (few epochs: the models are under-trained); the decoder's own
defaults (`--epochs 100`, early stopping with patience 10) give the full-size numbers.
Run: `.venv/bin/python bench/decoder_size.py [--data /work/data/nao_h2.zarr] [--epochs 8] [--floor 200]`.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.models.pixel import SIZES, PixelDecoder
from bodyschema.training.data import as_float, load_dataset

SIZE_NAMES = ("lean", "pixel_aif")


def seconds(fn, repeats: int, warmup: int = 2) -> float:
    for _ in range(warmup):   # oneDNN primitive creation, allocator
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def fit(size: str, data, epochs: int, progress: bool) -> tuple[PixelDecoder, list[float]]:
    """One decoder of `size` on the store's train split, early-stopped on its validation split."""
    epoch_seconds = []
    model = PixelDecoder(data.body, "image", data.output_shape("image"), size=size, epochs=epochs)
    model.fit(data.train.q, data.train.x, val=(data.val.q, data.val.x), progress=progress,
              on_epoch=lambda epoch, m: epoch_seconds.append(m["epoch_seconds"]))
    return model, epoch_seconds


def vjp_us(model: PixelDecoder, batch: int, repeats: int) -> tuple[float, float]:
    """µs per sample: batched `vjp`, and `predict_and_vjp` (forward + one VJP), at `batch` latents."""
    gen = torch.Generator().manual_seed(1)
    z = model.body.from_unit(torch.rand(batch, model.latent_dim, generator=gen) * 2 - 1)   # (B, Dz) rad
    v = torch.randn(batch, *model.output_shape, generator=gen)                             # (B, H, W)

    def both():
        _, vjp = model.predict_and_vjp(z)
        vjp(v)

    scale = 1e6 / batch
    return seconds(lambda: model.vjp(z, v), repeats) * scale, seconds(both, repeats) * scale


def floor_deg(model: PixelDecoder, data, n: int) -> dict[str, float]:
    """Perception started at the true pose of `n` held-out images: where it ends, in deg from the truth."""
    q = torch.as_tensor(data.val.q[:n], dtype=torch.float64)                              # (n, Dz) rad
    x = as_float(data.val.x[:n])                                                          # (n, H, W) in [0, 1]
    start = time.perf_counter()
    result = Perception(models=[model], config=PerceptionConfig(step_control="descent")).infer({"image": x}, mu0=q)
    err = (result.mu - q).abs().rad2deg()                                                 # (n, Dz) deg
    return {"mean": float(err.mean()), "median": float(err.median()), "p90_pose": float(err.mean(1).quantile(0.9)),
            "steps": float(result.steps.float().mean()), "seconds": time.perf_counter() - start}


def mean_image_mse(data) -> float:
    """MSE per pixel of predicting the mean validation image for every pose: the no-model baseline."""
    x = as_float(data.val.x)
    return float((x - x.mean(0)).pow(2).mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="/work/data/nao_h2.zarr", help="image store from `bodyschema datagen`")
    parser.add_argument("--epochs", type=int, default=8, help="max epochs per size (early stopping: patience 10)")
    parser.add_argument("--max-train", type=int, default=None, help="cap on training samples")
    parser.add_argument("--floor", type=int, default=200, help="held-out poses for the start-at-truth floor")
    parser.add_argument("--batch", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    parser.add_argument("--progress", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    data = load_dataset(args.data, "image", max_train=args.max_train)
    print(f"{args.data}: {data.body.robot}, images {data.output_shape('image')}, train {len(data.train)}, "
          f"val {len(data.val)}; {args.threads} threads, ≤ {args.epochs} epochs; mean-image MSE "
          f"{mean_image_mse(data):.3e}")
    rows = {}
    for size in SIZE_NAMES:
        model, epoch_s = fit(size, data, args.epochs, args.progress)
        vjp, both = vjp_us(model, args.batch, args.repeats)
        rows[size] = {"params": sum(p.numel() for p in model.net_.parameters()),
                      "epochs run": len(epoch_s), "s / epoch": statistics.median(epoch_s),
                      "val MSE": model.residual_var_,
                      "val MSE / mean-image MSE": model.residual_var_ / mean_image_mse(data),
                      f"VJP µs/sample @{args.batch}": vjp, f"pred+VJP µs/sample @{args.batch}": both,
                      **{f"floor {k} (deg)" if k in ("mean", "median", "p90_pose") else f"floor {k}": v
                         for k, v in floor_deg(model, data, args.floor).items()}}
        print(f"  {size} {SIZES[size]}: " + ", ".join(f"{k} {v:.4g}" for k, v in rows[size].items()), flush=True)
    print(f"\n{'':34}{'lean':>12}{'pixel_aif':>12}{'ratio':>9}")
    for key in rows["lean"]:
        a, b = rows["lean"][key], rows["pixel_aif"][key]
        fmt = (lambda v: f"{v:12,d}") if isinstance(a, int) else (lambda v: f"{v:12.4g}")
        print(f"{key:34}{fmt(a)}{fmt(b)}{b / a if a else float('nan'):9.2f}")


if __name__ == "__main__":
    main()
