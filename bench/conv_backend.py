"""The pixel decoder's inference calls with and without oneDNN, per batch size: where `ONEDNN_MIN_BATCH` comes from.

    .venv/bin/python bench/conv_backend.py [--decoder DIR] [--batches 1 2 4 8 32 128] [--threads 1] [--repeats 200]

Per batch B of latents: predict, predict_and_jacobian (forward mode, B·(1 + Dz) rows through each layer; up to
B = 32) and predict_and_vjp with its VJP (what an Adam step runs), each with oneDNN's convolutions and with PyTorch's
own, timed in turn within each repeat (fair under a varying load). Prints the medians and the ratio native / oneDNN
(< 1: the native convolutions are faster), and which path the decoder takes at that batch.
"""

from __future__ import annotations

import argparse

import torch
from jacobian import interleaved_medians  # bench/jacobian.py: this folder is on sys.path when run as a script
from tracking_jacobian import lean_decoder

from bodyschema.models import pixel
from bodyschema.models.contract import load_model

JACOBIAN_MAX_BATCH = 32


def with_onednn(enabled: bool, call):
    """call, run with oneDNN on or off (main lifts the decoder's own switch)."""
    def run():
        before = torch.backends.mkldnn.enabled
        torch.backends.mkldnn.enabled = enabled
        try:
            return call()
        finally:
            torch.backends.mkldnn.enabled = before
    return run


def calls(model, b: int) -> dict:
    z = torch.rand(b, model.latent_dim, generator=torch.Generator().manual_seed(b)) * 0.5
    v = torch.rand(b, *model.output_shape, generator=torch.Generator().manual_seed(b + 1))
    out = {"predict": lambda: model.predict(z), "predict_and_vjp": lambda: model.predict_and_vjp(z)[1](v)}
    if b <= JACOBIAN_MAX_BATCH:
        out["predict_and_jacobian"] = lambda: model.predict_and_jacobian(z)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--decoder", default=None, help="a saved pixel decoder's folder (default: the lean one)")
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 2, 4, 8, 32, 128])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model = load_model(args.decoder) if args.decoder else lean_decoder()
    threshold, pixel.ONEDNN_MIN_BATCH = pixel.ONEDNN_MIN_BATCH, 0      # the decoder leaves the flag as set here
    print(f"ms per call, {args.threads} thread(s); the decoder uses oneDNN from B = {threshold}")
    for b in args.batches:
        fns = {f"{name} {path}": with_onednn(path == "oneDNN", call)
               for name, call in calls(model, b).items() for path in ("oneDNN", "native")}
        ms = {k: 1e3 * v for k, v in interleaved_medians(fns, args.repeats)[0].items()}
        used = "oneDNN" if b >= threshold else "native"
        for name in calls(model, b):
            one, native = ms[f"{name} oneDNN"], ms[f"{name} native"]
            print(f"  B={b:<4d} {name:21s} oneDNN {one:8.3f}  native {native:8.3f}  native/oneDNN {native / one:5.2f}"
                  f"  (decoder: {used})")


if __name__ == "__main__":
    main()
