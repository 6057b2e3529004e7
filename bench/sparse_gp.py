"""`gpr` and `svgp` on N poses of a 6-joint arm's ee_xyz, side by side (issue 36 item 4; issue 33's kernel).

    MUJOCO_GL=egl .venv/bin/python bench/sparse_gp.py [--n 100000] [--exact-n 5000] [--robot PATH|NAME]
        [--num-inducing 1000] [--hyper-points 2000] [--elbo-epochs 0] [--threads 2] [--n-test 2000]
        [--kinds "gpr rbf" gpr svgp]

The arm: dm_control's Kinova Jaco (6 joints, from the test extra) unless --robot names another. Poses are uniform
in its sampling ranges (seeded), targets its forward kinematics (`Robot.fk`, m, noise-free): the kinematic-only
store `bodyschema datagen --no-images` would hold, without the Zarr round trip. The fits: "gpr rbf" (the exact GP
with the RBF kernel on a random --exact-n of the poses, its `max_points`: the baseline), "gpr" (the default kernel
choice; the kinematic kernel takes every pose in its feature form) and "svgp" (all N). Printed per fit: wall time,
held-out mean / max ee error (mm) on --n-test poses, Jacobian RMSE (m/rad) against the MuJoCo Jacobian, and
predict + Jacobian time per 500 poses (`predict_with_jacobian`, best of 5); then the ratios to "gpr rbf".
Targets (svgp): fit ≤ 600 s, error ratio < 1, predict+Jacobian ratio ≤ ~1 (the levels' cost per trial).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import time

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from bodyschema.datagen.body.robot import Robot
from bodyschema.models import BodySpec
from bodyschema.models.gpr import GPRModel
from bodyschema.models.svgp import SVGPModel

FIT_LIMIT_S = 600.0


def default_robot() -> str:
    """dm_control's Jaco MJCF (6 joints) when installed, else the shipped panda (7)."""
    try:
        return str(importlib.metadata.distribution("dm_control").locate_file(
            "dm_control/third_party/kinova/jaco_arm.xml"))
    except importlib.metadata.PackageNotFoundError:
        return "panda"


def predict_seconds(model, q: torch.Tensor, repeats: int = 5) -> float:
    """Best wall time of predict + Jacobian on q (500, Dz)."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        model.predict_with_jacobian(q)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000)
    parser.add_argument("--exact-n", type=int, default=5000)
    parser.add_argument("--robot", default=None)
    parser.add_argument("--num-inducing", type=int, default=1000)
    parser.add_argument("--hyper-points", type=int, default=2000)
    parser.add_argument("--elbo-epochs", type=int, default=0)
    parser.add_argument("--n-test", type=int, default=2000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--kinds", nargs="+", default=["gpr rbf", "gpr", "svgp"],
                        choices=["gpr rbf", "gpr", "svgp"], help="which fits to run, side by side")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    with threadpool_limits(limits=args.threads):
        run(args)


def run(args: argparse.Namespace) -> None:
    robot = Robot.load(args.robot or default_robot())
    low, high = robot.sampling_ranges[:, 0], robot.sampling_ranges[:, 1]
    body = BodySpec(robot.name, robot.joint_names, tuple(map(float, low)), tuple(map(float, high)))
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    q = rng.uniform(low, high, size=(args.n, len(low)))                           # (N, Dz) rad
    x = robot.fk(q)                                                                # (N, 3) m
    q_test = rng.uniform(low, high, size=(args.n_test, len(low)))
    x_test, j_test = torch.as_tensor(robot.fk(q_test)), torch.as_tensor(robot.jacobian(q_test))
    q_test = torch.as_tensor(q_test)
    print(f"robot {robot.name} ({len(low)} joints): {args.n} poses in {time.perf_counter() - start:.1f} s; "
          f"{args.n_test} held out; {args.threads} thread(s); load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores")
    makers = {
        "gpr rbf": lambda: GPRModel(body, "ee_xyz", (3,), max_points=args.exact_n, kernel="rbf"),
        "gpr": lambda: GPRModel(body, "ee_xyz", (3,), max_points=args.exact_n),
        "svgp": lambda: SVGPModel(body, "ee_xyz", (3,), num_inducing=args.num_inducing,
                                  hyper_points=args.hyper_points, elbo_epochs=args.elbo_epochs),
    }
    rows = {}
    for name in args.kinds:
        start = time.perf_counter()
        model = makers[name]().fit(q, x, seed=0)
        fit = time.perf_counter() - start
        err = (model.predict(q_test) - x_test).norm(dim=-1) * 1e3                  # (n_test,) mm
        jac = (model.jacobian(q_test) - j_test).pow(2).mean().sqrt()               # m/rad
        pj = predict_seconds(model, q_test[:500])
        rows[name] = (fit, float(err.mean()), float(jac), pj)
        used = args.n if name == "svgp" else model.train_u_.shape[0]
        kernel = f" ({model.kernel_})" if name.startswith("gpr") else ""
        print(f"  {name + kernel:18s} on {used:6d} poses: fit {fit:7.1f} s   mean err {err.mean():10.6f} mm   max "
              f"{err.max():9.5f} mm   J RMSE {jac:.2e} m/rad   predict+J {pj * 1e3:6.2f} ms / 500 poses",
              flush=True)
    if "gpr rbf" in rows:
        base = rows["gpr rbf"]
        for name in (k for k in rows if k != "gpr rbf"):
            fit, err, _, pj = rows[name]
            print(f"{name} / gpr rbf: fit {fit / base[0]:.2f}  mean error {err / base[1]:.2g}  predict+J "
                  f"{pj / base[3]:.2f}")
    if "svgp" in rows and "gpr rbf" in rows:
        fit_s, err_s, _, pj_s = rows["svgp"]
        print(f"targets (svgp against the RBF gpr on its {args.exact_n}): fit ≤ {FIT_LIMIT_S:.0f} s: "
              f"{'met' if fit_s <= FIT_LIMIT_S else 'NOT met'}; error ratio < 1: "
              f"{'met' if err_s < rows['gpr rbf'][1] else 'NOT met'}; predict+J ratio ≤ 1: "
              f"{'met' if pj_s <= rows['gpr rbf'][3] else 'NOT met'}")


if __name__ == "__main__":
    main()
