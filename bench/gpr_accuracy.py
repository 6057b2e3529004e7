"""Accuracy and training time of `gpr` and `sklearn-gpr` on a robot's ee_xyz, against the true kinematics.

    .venv/bin/python bench/gpr_accuracy.py [--robot nao_arm] [--n-train 2000] [--noise-mm 1.0] [--threads 1]
                                           [--hyper-all] [--cg-demo] [--skip-sklearn]

Training poses are uniform in the robot's sampling ranges (seeded); targets are `Robot.fk` (m), noise-free and
with Gaussian noise of --noise-mm per axis. Errors are always against the noise-free truth on held-out poses:
mean / max Euclidean error (mm), Jacobian RMSE over all entries vs `Robot.jacobian` (m/rad), the mean predicted
std (mm, from the precision) and the training time (s, wall and CPU: the CPU time is what a
quiet machine would take with one thread).
--hyper-all   also fits gpr's hyper-parameters on all training points (vs the default 500-point subset).
--cg-demo     also predicts with gpytorch's default settings (approximate CG solves above 800 points).
"""

from __future__ import annotations

import argparse
import time

import gpytorch
import numpy as np
import torch

from bodyschema.datagen.robot import Robot
from bodyschema.models import BodySpec
from bodyschema.models.gpr import GPRModel
from bodyschema.models.sklearn_gpr import SklearnGPRModel


def evaluate(model, q_test: torch.Tensor, x_test: torch.Tensor, j_test: torch.Tensor) -> dict[str, float]:
    err_mm = (model.predict(q_test) - x_test).norm(dim=-1) * 1e3                # (N,) mm
    jac_rmse = (model.jacobian(q_test) - j_test).pow(2).mean().sqrt()            # m/rad
    std_mm = model.precision(q_test).rsqrt().mean() * 1e3
    return {"mean_mm": float(err_mm.mean()), "max_mm": float(err_mm.max()), "jac_rmse": float(jac_rmse),
            "std_mm": float(std_mm)}


def report(name: str, seconds: float, cpu: float, metrics: dict[str, float]) -> None:
    print(f"  {name:26s} train {seconds:6.1f} s wall {cpu:6.1f} s CPU   mean err {metrics['mean_mm']:.4f} mm"
          f"   max {metrics['max_mm']:.3f} mm"
          f"   J RMSE {metrics['jac_rmse']:.2e} m/rad   pred. std {metrics['std_mm']:.4f} mm")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="nao_arm")
    parser.add_argument("--n-train", type=int, default=2000)
    parser.add_argument("--n-test", type=int, default=2000)
    parser.add_argument("--noise-mm", type=float, default=1.0)
    parser.add_argument("--hyper-points", type=int, default=500)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--hyper-all", action="store_true")
    parser.add_argument("--cg-demo", action="store_true")
    parser.add_argument("--skip-sklearn", action="store_true")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    robot = Robot.load(args.robot)
    low, high = robot.sampling_ranges[:, 0], robot.sampling_ranges[:, 1]
    body = BodySpec(robot.name, robot.joint_names, tuple(map(float, low)), tuple(map(float, high)))
    rng = np.random.default_rng(0)
    q_train = rng.uniform(low, high, size=(args.n_train, len(low)))            # (N, Dz) rad
    q_test = rng.uniform(low, high, size=(args.n_test, len(low)))
    x_clean = robot.fk(q_train)                                                  # (N, 3) m
    x_noisy = x_clean + rng.normal(0.0, args.noise_mm * 1e-3, size=x_clean.shape)
    test = (torch.as_tensor(q_test), torch.as_tensor(robot.fk(q_test)), torch.as_tensor(robot.jacobian(q_test)))
    print(f"robot {robot.name}: {args.n_train} training poses, {args.n_test} held-out, torch threads "
          f"{torch.get_num_threads()}; hyper-parameters on {args.hyper_points} points")

    kinds = [("gpr", lambda: GPRModel(body, "ee_xyz", (3,), hyper_points=args.hyper_points))]
    if args.hyper_all:
        kinds.append(("gpr, hyper on all points", lambda: GPRModel(body, "ee_xyz", (3,), hyper_points=args.n_train)))
    if not args.skip_sklearn:
        kinds.append(("sklearn-gpr", lambda: SklearnGPRModel(body, "ee_xyz", (3,), hyper_points=args.hyper_points)))
    for label, x_train in (("noise-free", x_clean), (f"{args.noise_mm:g} mm noise", x_noisy)):
        print(f"{label} targets:")
        for name, make in kinds:
            start, start_cpu = time.perf_counter(), time.process_time()
            model = make().fit(q_train, x_train, progress=False)
            seconds, cpu = time.perf_counter() - start, time.process_time() - start_cpu
            report(name, seconds, cpu, evaluate(model, *test))
            if name == "gpr":
                print(f"    lengthscales (unit) {model.lengthscale_.numpy().round(3).tolist()}  noise (std. units) "
                      f"{model.noise_.numpy().tolist()}")
            if name == "gpr" and args.cg_demo:
                cg_demo(model, test)


def cg_demo(model: GPRModel, test) -> None:
    """Posterior mean of the same GP through gpytorch with its default max_cholesky_size (800)."""
    gp = model.to_gpytorch()
    u = model.body.to_unit(test[0])                                              # (N, Dz)
    with torch.no_grad(), gpytorch.settings.skip_posterior_variances():
        mean = gp(u.expand(3, *u.shape)).mean.T * model.y_std_ + model.y_mean_   # (N, 3) m
    err_mm = (mean - test[1]).norm(dim=-1) * 1e3
    print(f"    gpytorch default solves (CG above {gpytorch.settings.max_cholesky_size.value()} points): "
          f"mean err {err_mm.mean():.4f} mm, max {err_mm.max():.3f} mm")


if __name__ == "__main__":
    main()
