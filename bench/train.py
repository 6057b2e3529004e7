"""Pixel-decoder training throughput: `bodyschema.training.train` vs a bare torch loop of the same network.

Both train the same `PixelDecoderNet` (same init, batch size, Adam, lr) for the same epochs on the same
training rows, in this one process. The bare loop has the data as in-memory float tensors and does nothing
else; `train` reads the Zarr store, validates each epoch, checkpoints, logs to MLflow (a fresh sqlite store in a
temp dir), plots, logs and registers the model. Reported (images/s = epochs × training images / seconds):
    fit    — `train`'s fit phase (per-epoch validation, checkpoint, metric logging included) vs bare: target ≥ 90 %
    total  — the whole `train` call, fixed costs (store read, MLflow, plots, registration) included
The bare loop runs before and after `train`; its mean is the baseline. Wall-clock and process CPU seconds are
both reported: on a shared machine the CPU-time ratio is the steadier of the two.

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
from bodyschema.models.configs import PixelConfig
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
    from bodyschema.datagen.store.schema import is_complete

    out = Path(tempfile.gettempdir()) / f"bodyschema-bench-planar2-{args.n}-{args.image_size}.zarr"
    if not is_complete(out):
        generate(DatagenConfig(robot="planar2", n=args.n, images=True, image_size=(args.image_size,) * 2,
                               out=out, overwrite=True, workers=1), progress=True)
    return out


def clocks() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def bare_loop(model: PixelDecoder, u: torch.Tensor, x: torch.Tensor, epochs: int) -> tuple[float, float]:
    """(wall s, CPU s) for `epochs` of plain minibatch Adam on in-memory tensors (the baseline)."""
    gen = torch.Generator().manual_seed(SEED)
    net = fast_layout(build(model._factory, gen))
    opt = torch.optim.Adam(net.parameters(), lr=LR)
    net.train()
    start = clocks()
    for _ in range(epochs):
        perm = torch.randperm(len(u), generator=gen)
        for i in range(0, len(u), BATCH):
            idx = perm[i:i + BATCH]
            loss = _mse(net, u[idx], x[idx])
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
    return tuple(b - a for a, b in zip(start, clocks()))


def timed_fit(record: list) -> None:
    """Wrap PixelDecoder.fit so the fit phase inside `train` is timed in wall and CPU seconds."""
    fit = PixelDecoder.fit

    def wrapper(self, *args, **kwargs):
        start = clocks()
        try:
            return fit(self, *args, **kwargs)
        finally:
            record.append(tuple(b - a for a, b in zip(start, clocks())))

    PixelDecoder.fit = wrapper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=3000, help="samples in the generated store")
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--image-size", type=int, default=64, help="px, square")
    parser.add_argument("--data", default=None, help="an existing image store instead of a generated one")
    args = parser.parse_args()
    store = dataset(args)
    hyper = PixelConfig(epochs=args.epochs, patience=args.epochs, batch_size=BATCH, lr=LR)

    data = load_dataset(store, "image", seed=SEED)            # the same split `train` makes
    model = PixelDecoder(data.body, "image", data.output_shape("image"))
    u, x = data.body.to_unit(torch.as_tensor(data.train.q)), as_float(data.train.x)    # (N, Dz), (N, H, W)
    n_images = args.epochs * len(u)
    print(f"store {store}: {len(u)} training images {tuple(x.shape[1:])}, {args.epochs} epochs, "
          f"torch threads {torch.get_num_threads()}, cpus {os.cpu_count()}")

    bare_loop(model, u[:4 * BATCH], x[:4 * BATCH], 1)          # warm-up (oneDNN kernels, allocator)
    bare = [bare_loop(model, u, x, args.epochs)]
    fits: list[tuple[float, float]] = []
    timed_fit(fits)
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        os.chdir(tmp)                                          # fresh sqlite store and artifacts, thrown away
        try:
            start = clocks()
            result = train(TrainConfig(model=hyper, data=store.resolve(), modality="image",
                                       seed=SEED, progress=False, tracking_uri=f"sqlite:///{tmp}/mlflow.db"))
            total = tuple(b - a for a, b in zip(start, clocks()))
        finally:
            os.chdir(cwd)
    bare.append(bare_loop(model, u, x, args.epochs))
    baseline = tuple(sum(b[i] for b in bare) / len(bare) for i in (0, 1))

    def row(label: str, seconds: tuple[float, float], target: str = "") -> None:
        print(f"{label:<16}" + "".join(f" {clock}: {n_images / s:7.1f} img/s ({s:6.1f} s, ratio {b / s:6.1%})"
                                       for clock, s, b in zip(("wall", "cpu"), seconds, baseline)) + target)

    print(f"{'bare torch loop':<16}" + "".join(f" {clock}: {n_images / s:7.1f} img/s ({s:6.1f} s)" for clock, s in
                                            zip(("wall", "cpu"), baseline))
          + f"   runs (wall) {bare[0][0]:.1f}, {bare[1][0]:.1f} s")
    row("train fit phase", fits[0], "   target ≥ 90 %")
    row("train total", total)
    print(f"val_rmse {result.metrics['val_rmse']:.4f} · registered {result.registered_name} v{result.model_version}")


if __name__ == "__main__":
    main()
