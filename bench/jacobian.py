"""Closed-form GP Jacobian (`gpr`) vs autograd through gpytorch's posterior mean, side by side in one run.

    .venv/bin/python bench/jacobian.py [--n-train 1000] [--n-query 500] [--threads 1] [--repeats 20]

Fits a `gpr` model on nao_arm ee_xyz (falls back to the planar2 robot when nao_arm is missing), then times
- closed form: `model.jacobian(z)` — kernel matrix, w = α ⊙ k, one matmul (see models/_gp_math.py);
- autograd (baseline): `model.to_gpytorch()` in eval mode, exact solves, variances skipped, one backward pass
  per output dimension through gpytorch's predictive mean (its cached α is warmed up first and not timed);
- autograd through our own closed-form mean (for reference).
Prints the median timings, the ratios against the gpytorch baseline, and the largest difference (m/rad).
"""

from __future__ import annotations

import argparse
import statistics
import time

import gpytorch
import numpy as np
import torch

from bodyschema.datagen.body.robot import Robot
from bodyschema.models import BodySpec
from bodyschema.models.gpr import GPRModel


def load_robot() -> Robot:
    try:
        return Robot.load("nao_arm")
    except Exception as exc:   # noqa: BLE001 — a bench falls back rather than stops
        print(f"nao_arm unavailable ({exc}); using planar2")
        return Robot.load("planar2")


def interleaved_medians(fns: dict, repeats: int) -> tuple[dict[str, float], dict[str, torch.Tensor]]:
    """Median seconds of each function, timed in turn within each repeat (fair under a varying machine load)."""
    outputs = {name: fn() for name, fn in fns.items()}            # warm-up, and the results to compare
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}, outputs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-train", type=int, default=1000)
    parser.add_argument("--n-query", type=int, default=500)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1: OpenMP threads stall on a loaded machine)")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    robot = load_robot()
    low, high = robot.sampling_ranges[:, 0], robot.sampling_ranges[:, 1]
    body = BodySpec(robot.name, robot.joint_names, tuple(map(float, low)), tuple(map(float, high)))
    rng = np.random.default_rng(0)
    q = rng.uniform(low, high, size=(args.n_train, len(low)))                  # (N, Dz) rad
    model = GPRModel(body, "ee_xyz", (3,), hyper_points=300).fit(q, robot.fk(q), progress=False)
    z = torch.as_tensor(rng.uniform(low, high, size=(args.n_query, len(low))))  # (B, Dz) rad
    n_out = 3

    gp = model.to_gpytorch()

    def gpytorch_autograd() -> torch.Tensor:
        u = body.to_unit(z).requires_grad_(True)                                # (B, Dz)
        with gpytorch.settings.max_cholesky_size(10**7), gpytorch.settings.skip_posterior_variances():
            mean = gp(u.expand(n_out, *u.shape)).mean                           # (O, B) standardized
        rows = [torch.autograd.grad(mean[o].sum(), u, retain_graph=o < n_out - 1)[0] for o in range(n_out)]
        jac_u = torch.stack(rows, 1)                                            # (B, O, Dz)
        return jac_u * model.y_std_[:, None] * body.unit_per_rad(z)

    def own_mean_autograd() -> torch.Tensor:
        zz = z.clone().requires_grad_(True)
        mean = model._predict(zz)                                               # (B, O)
        rows = [torch.autograd.grad(mean[:, o].sum(), zz, retain_graph=o < n_out - 1)[0] for o in range(n_out)]
        return torch.stack(rows, 1)                                             # (B, O, Dz)

    t, j = interleaved_medians({"closed": lambda: model.jacobian(z), "gpytorch": gpytorch_autograd,
                                "own": own_mean_autograd}, args.repeats)
    t_closed, t_gpytorch, t_own = t["closed"], t["gpytorch"], t["own"]
    j_closed, j_gpytorch, j_own = j["closed"], j["gpytorch"], j["own"]

    print(f"robot {robot.name}, {model.train_u_.shape[0]} training points, {args.n_query} queries, "
          f"torch threads {torch.get_num_threads()}, median of {args.repeats}")
    print(f"  closed form                 {t_closed * 1e3:8.2f} ms")
    print(f"  autograd through gpytorch   {t_gpytorch * 1e3:8.2f} ms   closed form is "
          f"{t_gpytorch / t_closed:5.1f}x faster   max |diff| {(j_closed - j_gpytorch).abs().max():.2e} m/rad")
    print(f"  autograd through own mean   {t_own * 1e3:8.2f} ms   closed form is "
          f"{t_own / t_closed:5.1f}x faster   max |diff| {(j_closed - j_own).abs().max():.2e} m/rad")
    print(f"  (max |J| {j_closed.abs().max():.3f} m/rad)")


if __name__ == "__main__":
    main()
