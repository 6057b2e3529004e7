"""Benchmark of the AIF perception update (a script, not a test): `python bench/aif.py [--quick] [--model SPEC ...]`.

Prints, measured in the same run:
  1. batched update of N trials vs a per-trial loop of the same math (wall time, ratio, max |Δμ|), for analytic
     oracles and for the --model problem (the 56×80 pixel decoder: "models:/bodyschema-nao_arm-image-pixel@champion");
  2. for an image decoder given with --model: every perception update side by side — Pixel-AIF's plain protocol
     with its own precisions (Euler Δt 0.1, Σ_v = 2·10⁴, at level 3 2·10³ then ×10 once the image MSE ≤ 0.01;
     5000 steps, on --plain-trials trials), the Gauss–Newton descent flow, Levenberg–Marquardt, Adam and the
     levels' default —: the start-at-truth floor first, then levels 1–3 with mean / median error, % of trials with
     every joint ≤ 2°, the gap to the floor, decoder evaluations per trial and wall time;
  3. wall time and results of the full levels benchmark (levels 1–3 and 3 with multi-start, N trials × runs) for
     analytic oracles on planar2 and nao_arm, and for any extra model given with --model (e.g. a pixel decoder
     "models:/bodyschema-nao_arm-image-pixel@champion" or a saved model directory);
  4. with --train-pixel N: a pixel decoder fitted here on N planar2 renders, through the same levels benchmark.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.aif.perception_config import FlowSettings
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.specs import load_robot, resolve_model
from bodyschema.evaluation.levels.benchmark import LevelsConfig, run_levels
from bodyschema.evaluation.levels.plain import PLAIN_STEPS, plain_infer
from bodyschema.evaluation.levels.report import markdown
from bodyschema.evaluation.levels.targets import initial_beliefs, make_targets

SIGMA = {"ee_xyz": 1e-3, "ee_pixel": 1.0, "joints": math.radians(2.0)}   # m, px, rad: noise = 1/√precision
COLUMNS = ("joint_err_deg", "joint_err_median_deg", "ee_err_mm", "success", "steps", "evaluations_per_trial",
           "diverged", "wall_s")


def problem(models, n: int, level: int = 2, seed: int = 0, noise=None):
    """The benchmark robot of `models`, n level-`level` trials (targets, observations, μ0) of run 0."""
    robot = load_robot(models)
    image = any(m.modality == "image" for m in models)
    targets = make_targets(robot, n, eval_rng(seed, 0, "targets"), image, noise, eval_rng(seed, 0, "noise"))
    rng = eval_rng(seed, 0, "beliefs", level)
    mu0 = torch.from_numpy(initial_beliefs(level, targets.q, robot.sampling_ranges, rng))
    return targets, mu0


def analytic(robot_name: str, modalities):
    """Analytic models of `modalities`, their precisions 1/σ² and the joint-sensor noise that goes with them."""
    models = [resolve_model(f"analytic:{robot_name}:{m}") for m in modalities]
    return models, {m: SIGMA[m] ** -2 for m in modalities}, {m: SIGMA[m] for m in modalities if m == "joints"}


def label(models) -> str:
    return f"{models[0].body.robot} " + "+".join(f"{m.modality}({getattr(m, 'kind', '?')})" for m in models)


def batched_vs_loop(models, n, precisions=None, noise=None):
    targets, mu0 = problem(models, n, noise=noise)
    perception = Perception(models, replace(LevelsConfig().perception, record=False), precisions)
    obs = targets.tensors([m.modality for m in models])
    t = time.perf_counter()
    batched = perception.infer(obs, mu0)
    t_batch = time.perf_counter() - t
    t = time.perf_counter()
    singles = [perception.infer({k: v[i:i + 1] for k, v in obs.items()}, mu0[i:i + 1]).mu for i in range(n)]
    t_loop = time.perf_counter() - t
    diff = (torch.cat(singles) - batched.mu).abs().amax(-1)               # (N,) rad
    print(f"[1] {label(models)}, {n} trials (level 2): batched {t_batch:.3f} s, per-trial loop {t_loop:.3f} s "
          f"→ ×{t_loop / t_batch:.1f}; |Δμ| batched vs loop max {diff.max():.2e} rad, median {diff.median():.2e} rad "
          f"(float32 networks round differently at batch 1 and N); mean steps {batched.steps.float().mean():.1f}")


def updates(models):
    """The updates compared in [2]: Pixel-AIF's plain protocol, the Gauss–Newton descent flow, LM, Adam, default."""
    default = Perception(models, LevelsConfig().perception).config       # "auto" resolved for these models
    return {"plain Pixel-AIF (Euler Δt 0.1, Π=1/Σ_v)": None,
            "Gauss–Newton descent (flow)": PerceptionConfig(method="flow", flow=FlowSettings(step_control="descent")),
            "Levenberg–Marquardt": PerceptionConfig(method="lm"),
            "Adam (first-order adaptive)": PerceptionConfig(method="adam"),
            "Adam, then LM in the basin": PerceptionConfig(method="adam+lm"),
            f"default ({default.method})": replace(default, record=False)}


def compare_updates(models, n, levels=(1, 2, 3), plain_n=100, plain_steps=5000):
    """[2] Every update on the same problems: the start-at-truth floor first, then each level and the gap to it."""
    print(f"[2] {label(models)}: updates side by side, {n} trials per level (plain protocol: {plain_n} trials, "
          f"{plain_steps} steps), mean |joint error| over joints and trials")
    header = f"    {'update':42s} {'level':>5s} {'mean°':>7s} {'median°':>8s} {'all≤2°':>7s} {'gap°':>7s} " \
             f"{'evals/trial':>11s} {'wall s':>7s}"
    print(header)
    problems = {}                                                          # rendered once per (trials, level)
    for name, cfg in updates(models).items():
        floors = {}
        for level in (0, *levels):                                         # 0: start at the truth
            key = (plain_n if cfg is None else n, max(level, 1))
            if key not in problems:
                problems[key] = problem(models, key[0], level=key[1])
            targets, mu0 = problems[key]
            obs = targets.tensors([m.modality for m in models])
            truth = torch.from_numpy(targets.q)
            start = truth if level == 0 else mu0
            t = time.perf_counter()
            res = plain_infer(models, obs, start, max(level, 1), plain_steps) if cfg is None else \
                Perception(models, cfg).infer(obs, start)
            wall = time.perf_counter() - t
            err = np.rad2deg((res.mu - truth).abs().numpy())                # (N, Dz) deg
            mean = err.mean()
            floors.setdefault(level, mean)
            gap = mean - floors[0]
            print(f"    {name:42s} {'floor' if level == 0 else str(level):>5s} {mean:7.3f} "
                  f"{np.median(err.mean(1)):8.3f} {100 * (err <= 2).all(1).mean():6.1f}% "
                  f"{'' if level == 0 else f'{gap:+7.3f}':>7s} {res.evaluations / len(err):11.1f} {wall:7.1f}")


def full_levels(models_spec, n, runs, out, label, precisions=(), noise=()):
    config = LevelsConfig(models=tuple(models_spec), trials=n, runs=runs, out=out / label, mlflow=False,
                          noise=tuple(noise),
                          perception=replace(LevelsConfig().perception, precisions=tuple(precisions)))
    t = time.perf_counter()
    summary = run_levels(config)
    wall = time.perf_counter() - t
    print(f"[3] {label}: full levels benchmark ({n} trials × {runs} runs, levels 1, 2, 3, 3+multi-start) "
          f"wall {wall:.1f} s (incl. simulator targets and plots)")
    print(markdown(summary.table, COLUMNS))


def train_pixel(robot_name: str, n: int, size: tuple[int, int], epochs: int):
    """A pixel decoder (bodyschema.models.pixel) fitted here on n rendered poses (datagen's seed stream, not the
    evaluation's): used when no registered one is given."""
    from bodyschema.datagen.body.robot import Robot
    from bodyschema.models.pixel import PixelDecoder
    from bodyschema.models.scaling import BodySpec
    robot = Robot.load(robot_name, image_size=size)
    rng = np.random.default_rng(np.random.SeedSequence([0, 0]))
    q = rng.uniform(robot.sampling_ranges[:, 0], robot.sampling_ranges[:, 1], size=(n, robot.dq))
    t = time.perf_counter()
    images = torch.from_numpy(robot.observe(q, image=True)["image"]).float() / 255.0
    t_render = time.perf_counter() - t
    body = BodySpec(robot.name, robot.joint_names, *map(tuple, robot.sampling_ranges.T))
    model = PixelDecoder(body, "image", size, fc_hidden=64, channels=(32, 16, 8), epochs=epochs, batch_size=64,
                         lr=2e-3, patience=epochs)
    split = int(0.9 * n)
    t = time.perf_counter()
    model.fit(torch.from_numpy(q[:split]).float(), images[:split], val=(torch.from_numpy(q[split:]).float(),
                                                                          images[split:]), progress=False)
    print(f"[4] pixel decoder on {robot_name} {size}: {n} renders {t_render:.1f} s, "
          f"fit {time.perf_counter() - t:.1f} s, validation residual variance {model.residual_var_:.2e} "
          f"(precision {model.precision_:.3g})")
    return model


def pixel_levels(model, n, runs, out, label, extra=()):
    config = LevelsConfig(trials=n, runs=runs, out=out / label, mlflow=False)
    t = time.perf_counter()
    summary = run_levels(config, models=[model, *extra])
    print(f"[4] {label}: full levels benchmark ({n} trials × {runs} runs) wall {time.perf_counter() - t:.1f} s")
    print(markdown(summary.table, COLUMNS + ("image_mse",)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100 trials, 1 run, 1000 plain steps")
    parser.add_argument("--model", action="append", default=[],
                        help="model spec(s) fused into one more problem for sections 1–3, e.g. a pixel decoder")
    parser.add_argument("--plain-trials", type=int, default=100,
                        help="trials of the plain protocol (5000 Euler steps each) for the --model problem")
    parser.add_argument("--out", type=Path, default=Path("results/bench_aif"))
    parser.add_argument("--train-pixel", type=int, default=0, metavar="N",
                        help="fit a pixel decoder on N planar2 renders (32×32) and run the levels with it")
    parser.add_argument("--pixel-epochs", type=int, default=40)
    parser.add_argument("--skip", type=int, nargs="*", default=[], help="sections to skip (1 2 3)")
    parser.add_argument("--trials", type=int, default=None,
                        help="trials per level (default: 500, --quick 100); the plain protocol keeps its 5000 steps")
    args = parser.parse_args()
    n, runs = (100, 1) if args.quick else (500, 5)
    n = args.trials or n
    plain_steps = 1000 if args.quick else PLAIN_STEPS
    torch.set_num_threads(1)
    nao = ("ee_xyz", "ee_pixel", "joints")
    oracles = [analytic("planar2", ("ee_xyz",)), analytic("nao_arm", ("ee_xyz", "joints")), analytic("nao_arm", nao)]
    extra = [resolve_model(spec) for spec in args.model]                  # e.g. the 56×80 pixel decoder
    if 1 not in args.skip:
        for models, precisions, noise in (oracles[0], oracles[2]):
            batched_vs_loop(models, n, precisions, noise)
        if extra:
            batched_vs_loop(extra, n)
    if 2 not in args.skip:
        if any(m.modality == "image" for m in extra):   # 5000 plain steps per trial: a subset of the trials
            compare_updates(extra, n, plain_n=min(n, args.plain_trials), plain_steps=plain_steps)
        else:
            print("[2] skipped: give an image decoder with --model "
                  "(e.g. models:/bodyschema-nao_arm-image-pixel@champion)")
    if 3 not in args.skip:
        full_levels(["analytic:planar2:ee_xyz"], n, runs, args.out, "planar2 ee_xyz")
        full_levels(["analytic:nao_arm:ee_xyz"], n, runs, args.out, "nao_arm ee_xyz")
        full_levels([f"analytic:nao_arm:{m}" for m in nao], n, runs, args.out, "nao_arm ee_xyz+ee_pixel+joints(σ 2°)",
                    precisions=[(m, SIGMA[m] ** -2) for m in nao], noise=[("joints", SIGMA["joints"])])
        if args.model:
            full_levels(args.model, n, runs, args.out, "+".join(args.model))
    if args.train_pixel:
        pixel = train_pixel("planar2", args.train_pixel, (32, 32), args.pixel_epochs)
        pixel.save(args.out / "pixel_decoder")               # reuse: --model trusted:<out>/pixel_decoder
        pixel_levels(pixel, n, runs, args.out, "planar2 pixel decoder (image)")

if __name__ == "__main__":
    main()
