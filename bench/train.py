"""Pixel-decoder training throughput: `bodyschema.training.train` vs a bare torch loop of the same network.

Both train the same `PixelDecoderNet` (same init, batch size, Adam, lr) for the same epochs on the same
training rows, in this one process. The bare loop has the data as in-memory float tensors and does nothing
else; `train` reads the Zarr store, validates each epoch, checkpoints, logs to MLflow (a fresh sqlite store in a
temp dir), plots, logs and registers the model. Reported (images/s = epochs × training images / seconds):
    fit    — `train`'s fit phase (per-epoch validation, checkpoint and metric logging included) vs bare: target ≥ 90 %
    total  — the whole `train` call, fixed costs (store read, MLflow, plots, registration) included
The bare loop runs before and after `train`; its mean is the baseline (the machine may be shared).

    python bench/train.py [--n 3000] [--epochs 4] [--image-size 64] [--data PATH]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import torch

from bodyschema.models._nn_fit import build
from bodyschema.models.pixel import PixelDecoder, _mse, fast_layout
from bodyschema.training.config import TrainConfig
from bodyschema.training.data import as_float, load_dataset
from bodyschema.training.train import train

BATCH, LR, SEED = 64, 2e-3, 0       # PixelDecoder's defaults


def dataset(args) -> Path:
    """The bench store: --data, else a planar2 image store generated once into the temp dir."""
    if args.data:
        return Path(args.data)
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate
    from bodyschema.datagen.store import is_complete

    out = Path(tempfile.gettempdir()) / f"bodyschema-bench-planar2-{args.n}-{args.image_size}.zarr"
    if not is_complete(out):
        generate(DatagenConfig(robot="planar2", n=args.n, images=True, image_size=(args.image_size,) * 2,
                               out=out, overwrite=True, workers=1), progress=True)
    return out


def bare_loop(model: PixelDecoder, u: torch.Tensor, x: torch.Tensor, epochs: int) -> float:
    """Seconds for `epochs` of plain minibatch Adam on in-memory tensors (the baseline)."""
    gen = torch.Generator().manual_seed(SEED)
    net = fast_layout(build(model._factory, gen))
    opt = torch.optim.Adam(net.parameters(), lr=LR)
    net.train()
    start = time.perf_counter()
    for _ in range(epochs):
        perm = torch.randperm(len(u), generator=gen)
        for i in range(0, len(u), BATCH):
            idx = perm[i:i + BATCH]
            loss = _mse(net, u[idx], x[idx])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=3000, help="samples in the generated store")
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--image-size", type=int, default=64, help="px, square")
    parser.add_argument("--data", default=None, help="an existing image store instead of a generated one")
    args = parser.parse_args()
    store = dataset(args)
    hyper = {"epochs": str(args.epochs), "patience": str(args.epochs), "batch_size": str(BATCH), "lr": str(LR)}

    data = load_dataset(store, "image", seed=SEED)            # the same split `train` makes
    model = PixelDecoder(data.body, "image", data.output_shape("image"))
    u, x = data.body.to_unit(torch.as_tensor(data.train.q)), as_float(data.train.x)    # (N, Dz), (N, H, W)
    n_images = args.epochs * len(u)
    print(f"store {store}: {len(u)} training images {tuple(x.shape[1:])}, {args.epochs} epochs, "
          f"torch threads {torch.get_num_threads()}, cpus {os.cpu_count()}")

    bare_loop(model, u[:4 * BATCH], x[:4 * BATCH], 1)          # warm-up (oneDNN kernels, allocator)
    bare = [bare_loop(model, u, x, args.epochs)]
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        os.chdir(tmp)                                          # fresh sqlite store and artifacts, thrown away
        try:
            start = time.perf_counter()
            result = train(TrainConfig(model="pixel", data=store.resolve(), modality="image", hyper=hyper,
                                       seed=SEED, progress=False, tracking_uri=f"sqlite:///{tmp}/mlflow.db"))
            total = time.perf_counter() - start
        finally:
            os.chdir(cwd)
    bare.append(bare_loop(model, u, x, args.epochs))
    baseline = sum(bare) / len(bare)
    fit = result.metrics["fit_seconds"]

    print(f"bare torch loop : {n_images / baseline:8.1f} images/s  ({baseline:.1f} s; runs {bare[0]:.1f}, {bare[1]:.1f})")
    print(f"train, fit phase: {n_images / fit:8.1f} images/s  ({fit:.1f} s)  ratio {baseline / fit:6.1%}  (target ≥ 90 %)")
    print(f"train, total    : {n_images / total:8.1f} images/s  ({total:.1f} s)  ratio {baseline / total:6.1%}")
    print(f"val_rmse {result.metrics['val_rmse']:.4f} · registered {result.registered_name} v{result.model_version}")


if __name__ == "__main__":
    main()
