"""The pixel decoder's Jacobian, the tracker's per-frame cost: four ways side by side in one run.

    .venv/bin/python bench/tracking_jacobian.py [--decoder DIR] [--batches 1 2 8] [--threads 1] [--repeats 200]
        [--inputs unit products kinematic]

- predict: one forward of B latents (the unit every other figure is divided by);
- vmap(jacfwd): autograd forward mode, Dz JVPs under vmap (the generic NetModel path, the baseline);
- forward_and_jacobian: the same JVPs written out, primal and tangents as one batch of B·(1 + Dz) per layer
  (what `PixelDecoder.jacobian` runs; the prediction comes with it);
- forward differences: one forward of B·(1 + Dz) latents, h = 1e-3 rad (float32: ~1e-2 relative error).
The lean decoder at 56×80 on nao_arm's joints, once per `--inputs` (what its first layer reads of the pose,
models/pose_inputs.py); `--decoder` times a saved one instead (weights do not change the
cost). Prints medians interleaved per repeat (fair under a varying load), ratios to vmap(jacfwd), and the largest
relative difference of each Jacobian to it.
"""

from __future__ import annotations

import argparse

import torch
from jacobian import interleaved_medians  # bench/jacobian.py: this folder is on sys.path when run as a script

from bodyschema.models._nn_model import NetModel
from bodyschema.models.contract import load_model
from bodyschema.models.pixel import PixelDecoder
from bodyschema.models.pose_inputs import DEFAULT_INPUTS, INPUTS
from bodyschema.models.scaling import BodySpec

FD_STEP = 1e-3    # rad: float32 forward differences, truncation ~h, rounding ~1e-7/h


def lean_decoder(inputs: str = DEFAULT_INPUTS) -> PixelDecoder:
    body = BodySpec("nao_arm", ("LShoulderPitch", "LShoulderRoll", "LElbowYaw", "LElbowRoll"),
                    (-0.115, 0.07, -1.585, -0.88), (0.58, 0.815, 1.07, -0.044))
    model = PixelDecoder(body, "image", (56, 80), inputs=inputs)
    model._set_net(model.new_net(torch.Generator().manual_seed(0)))
    model.precision_ = 1.0
    return model


def forward_differences(model, z: torch.Tensor) -> torch.Tensor:
    b, dz = z.shape
    shifted = (z[None] + FD_STEP * torch.eye(dz, dtype=z.dtype)[:, None]).reshape(-1, dz)   # (Dz·B, Dz)
    out = model.predict(torch.cat([z, shifted])).reshape(1 + dz, b, -1)                     # (1+Dz, B, O)
    return ((out[1:] - out[0]) / FD_STEP).permute(1, 2, 0)                                  # (B, O, Dz)


def methods(model, z: torch.Tensor) -> dict:
    return {"predict": lambda: model.predict(z), "vmap(jacfwd)": lambda: NetModel._jacobian(model, z),
            "forward_and_jacobian": lambda: model.jacobian(z),
            "forward differences": lambda: forward_differences(model, z)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--decoder", default=None, help="a saved pixel decoder directory (default: an untrained one)")
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 2, 8])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--inputs", nargs="+", default=list(INPUTS), help="what the decoders read of the pose")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    models = {"saved": load_model(args.decoder)} if args.decoder else {k: lean_decoder(k) for k in args.inputs}
    for name, model in models.items():
        print(f"-- {name}")
        table(model, args.batches, args.repeats)


def table(model, batches: list[int], repeats: int) -> None:
    gen = torch.Generator().manual_seed(1)
    print(f"{'B':>3} {'method':<22} {'ms':>8} {'vs jacfwd':>10} {'vs predict':>11} {'max rel. diff':>14}")
    for b in batches:
        z = model.body.from_unit(torch.rand(b, model.latent_dim, generator=gen) * 2 - 1)   # (B, Dz) rad, float32
        fns = methods(model, z)
        ms = {k: 1e3 * v for k, v in interleaved_medians(fns, repeats)[0].items()}
        reference = NetModel._jacobian(model, z)
        scale = float(reference.abs().max())
        for name, t in ms.items():
            diff = "" if name == "predict" else f"{float((fns[name]() - reference).abs().max()) / scale:14.1e}"
            print(f"{b:>3} {name:<22} {t:8.2f} {ms['vmap(jacfwd)'] / t:9.1f}x {t / ms['predict']:10.1f}x {diff}")


if __name__ == "__main__":
    main()
