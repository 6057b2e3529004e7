"""Benchmark: the pixel decoder's capacities ("lean" vs "pixel_aif") side by side on one image dataset.

Both sizes are trained in this run on the same store and split (`training.data.load_dataset`, seed 0), then:
  * parameters, training seconds per epoch (median), held-out MSE per pixel (intensity in [0, 1]) and that MSE
    relative to predicting the mean validation image;
  * µs per sample of one batched `vjp` at batch 500 and of `predict_and_vjp` (what an AIF step needs), float32;
  * the start-at-truth floor: perception (the flow under descent control) started at the *true*
    pose of `--floor` held-out images. A perfect decoder would stay there; the mean |joint error| (deg) it
    drifts to is the error the decoder alone imposes on image-only perception.
Ratios are pixel_aif / lean. VJP times are the minimum over repeats, the two models taking turns in every
repeat (the least disturbed run on a shared machine); s / epoch is measured while each trains, so it is not.
The defaults (all training images, 20 epochs, 100 floor poses) take ~10 min on 2 quiet cores (far more on a
shared machine), with models not yet converged; the report's numbers: `--epochs 30 --floor 200`.
Run: `.venv/bin/python bench/decoder_size.py [--data /work/data/nao_h2.zarr] [--sizes lean pixel_aif]`.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.aif.perception_config import FlowSettings
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


def vjp_us(models: dict[str, PixelDecoder], batch: int, repeats: int) -> dict[str, tuple[float, float]]:
    """µs per sample of batched `vjp` and of `predict_and_vjp` (forward + one VJP) at `batch` latents, per model.
    The models take turns within every repeat, so load from other processes hits them alike."""
    gen = torch.Generator().manual_seed(1)
    first = next(iter(models.values()))
    z = first.body.from_unit(torch.rand(batch, first.latent_dim, generator=gen) * 2 - 1)   # (B, Dz) rad
    v = torch.randn(batch, *first.output_shape, generator=gen)                             # (B, H, W)

    def both(model):
        _, vjp = model.predict_and_vjp(z)
        vjp(v)

    times = {name: ([], []) for name in models}
    for _ in range(repeats):
        for name, model in models.items():
            times[name][0].append(seconds(lambda model=model: model.vjp(z, v), 1, warmup=1))   # bound per turn
            times[name][1].append(seconds(lambda model=model: both(model), 1, warmup=0))
    return {name: (min(a) * 1e6 / batch, min(b) * 1e6 / batch) for name, (a, b) in times.items()}


def floor_deg(model: PixelDecoder, data, n: int) -> dict[str, float]:
    """Perception started at the true pose of `n` held-out images: where it ends, in deg from the truth."""
    q = torch.as_tensor(data.val.q[:n], dtype=torch.float64)                              # (n, Dz) rad
    x = as_float(data.val.x[:n])                                                          # (n, H, W) in [0, 1]
    start = time.perf_counter()
    config = PerceptionConfig(method="flow", flow=FlowSettings(step_control="descent"))
    result = Perception(models=[model], config=config).infer({"image": x}, mu0=q)
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
    parser.add_argument("--epochs", type=int, default=20, help="max epochs per size (early stopping: patience 10)")
    parser.add_argument("--max-train", type=int, default=0, help="cap on training samples (0: all)")
    parser.add_argument("--floor", type=int, default=100, help="held-out poses for the start-at-truth floor")
    parser.add_argument("--batch", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    parser.add_argument("--sizes", nargs="+", default=list(SIZE_NAMES), choices=SIZE_NAMES)
    parser.add_argument("--progress", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    data = load_dataset(args.data, "image", max_train=args.max_train or None)
    print(f"{args.data}: {data.body.robot}, images {data.output_shape('image')}, train {len(data.train)}, "
          f"val {len(data.val)}; {args.threads} threads, ≤ {args.epochs} epochs; mean-image MSE "
          f"{mean_image_mse(data):.3e}")
    models, rows = {}, {}
    for size in args.sizes:
        models[size], epoch_s = fit(size, data, args.epochs, args.progress)
        rows[size] = {"params": sum(p.numel() for p in models[size].net_.parameters()),
                      "epochs run": len(epoch_s), "s / epoch": statistics.median(epoch_s)}
    timings = vjp_us(models, args.batch, args.repeats)
    for size, model in models.items():
        vjp, both = timings[size]
        rows[size] = {**rows[size],
                      "val MSE": model.residual_var_,
                      "val MSE / mean-image MSE": model.residual_var_ / mean_image_mse(data),
                      f"VJP µs/sample @{args.batch}": vjp, f"pred+VJP µs/sample @{args.batch}": both,
                      **{f"floor {k} (deg)" if k in ("mean", "median", "p90_pose") else f"floor {k}": v
                         for k, v in floor_deg(model, data, args.floor).items()}}
        print(f"  {size} {SIZES[size]}: " + ", ".join(f"{k} {v:.4g}" for k, v in rows[size].items()), flush=True)
    both = len(rows) == 2
    print(f"\n{'':34}" + "".join(f"{size:>12}" for size in rows) + (f"{'ratio':>9}" if both else ""))
    for key in rows[args.sizes[0]]:
        values = [row[key] for row in rows.values()]
        cells = "".join(f"{v:12,d}" if isinstance(v, int) else f"{v:12.4g}" for v in values)
        ratio = f"{values[1] / values[0] if values[0] else float('nan'):9.2f}" if both else ""
        print(f"{key:34}{cells}{ratio}")


if __name__ == "__main__":
    main()
