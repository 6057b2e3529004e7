"""Benchmark: the pixel decoder's VJP for the AIF update — one batched call vs a per-sample loop.

The AIF benchmark updates every trial every step with forward + VJP of the image decoder, so its budget is
µs per sample-step for a batch of 500 on this machine's CPU cores. Measured in the same run:
  * our 56×80 grayscale `PixelDecoder` with default hyper-parameters: batched `vjp` over 500 latents,
    `predict_and_vjp` (prediction and VJP from one forward, what an AIF step needs), the same 500 VJPs one
    at a time, and the Jacobian route (build (B, 4480, Dz), then Jᵀv) it avoids;
  * a Pixel-AIF-style reference decoder (reconstructed pattern: FC 4→512→8×7×10, then three ×2 transposed
    convolutions each followed by a 3×3 convolution, 16/64 channels, ReLU, NCHW) with the same batched VJP.
Times are the minimum over repeats (the least disturbed run on a shared machine).
Run: `.venv/bin/python bench/pixel_vjp.py [--batch 500] [--repeats 10] [--threads N]`.
"""

from __future__ import annotations

import argparse
import time

import torch
from torch import nn

from bodyschema.models import BodySpec
from bodyschema.models.pixel import PixelDecoder

BODY = BodySpec("bench_arm", ("j0", "j1", "j2", "j3"), (-2.0, -1.5, -2.0, -1.5), (2.0, 1.5, 2.0, 1.5))
SHAPE = (56, 80)


def pixel_aif_reference() -> nn.Module:
    """Pixel-AIF-style decoder for 56×80 (as described above); weights are random: timing only."""
    return nn.Sequential(
        nn.Linear(4, 512), nn.ReLU(), nn.Linear(512, 8 * 7 * 10), nn.ReLU(), nn.Unflatten(1, (8, 7, 10)),
        nn.ConvTranspose2d(8, 16, 4, 2, 1), nn.ReLU(), nn.Conv2d(16, 16, 3, 1, 1), nn.ReLU(),     # 14×20
        nn.ConvTranspose2d(16, 64, 4, 2, 1), nn.ReLU(), nn.Conv2d(64, 64, 3, 1, 1), nn.ReLU(),    # 28×40
        nn.ConvTranspose2d(64, 1, 4, 2, 1), nn.Sigmoid()).requires_grad_(False)                  # 56×80


def fitted_decoder() -> PixelDecoder:
    """Default hyper-parameters; one quick epoch on random images: the timing does not depend on the weights."""
    gen = torch.Generator().manual_seed(0)
    q = BODY.from_unit(torch.rand(64, 4, generator=gen) * 2 - 1)
    x = torch.rand(64, *SHAPE, generator=gen)
    return PixelDecoder(BODY, "image", SHAPE, epochs=1).fit(q, x, progress=False)


def seconds(fn, repeats: int, warmup: int = 2) -> float:
    for _ in range(warmup):   # oneDNN primitive creation, allocator
        fn()
    times = []
    for _ in range(repeats):   # the minimum: the least disturbed run on a shared machine
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    b = args.batch
    model = fitted_decoder()
    gen = torch.Generator().manual_seed(1)
    z = BODY.from_unit(torch.rand(b, 4, generator=gen) * 2 - 1)           # (B, 4) rad
    v = torch.randn(b, *SHAPE, generator=gen)                             # (B, 56, 80)

    def per_sample():
        for i in range(b):
            model.vjp(z[i:i + 1], v[i:i + 1])

    def via_jacobian():
        torch.einsum("bod,bo->bd", model.jacobian(z), v.reshape(b, -1))

    reference = pixel_aif_reference()

    def reference_vjp():
        with torch.enable_grad():
            zz = BODY.to_unit(z).requires_grad_(True)
            torch.autograd.grad(reference(zz), zz, v[:, None])

    def forward_then_vjp():   # what an AIF step needs: the prediction (for the error) and Jᵀ(Π ε)
        x_hat, vjp = model.predict_and_vjp(z)
        vjp(v)

    t_batched = seconds(lambda: model.vjp(z, v), args.repeats)
    t_step = seconds(forward_then_vjp, args.repeats)
    t_forward = seconds(lambda: model.predict(z), args.repeats)
    t_loop = seconds(per_sample, 1, warmup=0)   # 500 calls: warm after the first few
    t_jac = seconds(via_jacobian, max(1, args.repeats // 5))
    t_ref = seconds(reference_vjp, max(1, args.repeats // 2))
    n_params = sum(p.numel() for p in model.net_.parameters())
    n_ref = sum(p.numel() for p in reference.parameters())
    us = 1e6 / b
    print(f"PixelDecoder 56×80 gray, defaults (fc_hidden={model.fc_hidden}, channels={model.channels}, "
          f"{n_params} params), batch {b}, {args.threads} threads")
    print(f"  batched vjp (forward + backward) : {t_batched * 1e3:8.1f} ms/batch  "
          f"{t_batched * us:7.1f} µs/sample-step")
    print(f"  predict_and_vjp (one forward)    : {t_step * 1e3:8.1f} ms/batch  {t_step * us:7.1f} µs/sample-step "
          f"(vs predict + vjp: {(t_forward + t_batched) * us:.1f})")
    print(f"  forward only (predict)           : {t_forward * 1e3:8.1f} ms/batch  {t_forward * us:7.1f} µs/sample")
    print(f"  per-sample vjp loop              : {t_loop * 1e3:8.1f} ms/batch  {t_loop * us:7.1f} µs/sample-step")
    print(f"  Jacobian (B, 4480, 4) then Jᵀv   : {t_jac * 1e3:8.1f} ms/batch  {t_jac * us:7.1f} µs/sample-step")
    print(f"  Pixel-AIF-style reference vjp    : {t_ref * 1e3:8.1f} ms/batch  {t_ref * us:7.1f} µs/sample-step "
          f"({n_ref} params)")
    print(f"ratios: loop / batched = {t_loop / t_batched:.1f}×, jacobian / batched = {t_jac / t_batched:.1f}×, "
          f"reference / ours = {t_ref / t_batched:.1f}×")


if __name__ == "__main__":
    main()
