"""Where the time of `bodyschema evaluate levels --encoder` goes, and what the speed-ups give (a script, not a test).

Prints, measured side by side in one run on the same targets (run 0 of the levels' seeds):
  [1] the protocol before / after: the former one ran every row on its own ("1+enc": a 2-start multi-start of the
      level's start and the encoder's guess, screened 1 step; every "+enc" row encoded the images again) and now each
      start is inferred once per run, the "+enc" rows taking per trial the lower F of the starts they share; per
      row mean and median error of both (they differ only by the former's screening step) and the wall ratio;
  [2] the decoder's share: µs per trial of predict, vjp, predict + vjp as two calls (what aif/free_energy.py
      does today) and `predict_and_vjp` (one forward), at the levels' batch, with 1 and 2 torch threads;
  [3] whole runs (`measure_levels`) in one process vs spread over --workers processes (1 torch thread each).

    MUJOCO_GL=egl OMP_NUM_THREADS=1 .venv/bin/python bench/levels_speed.py --model DIR --encoder DIR \
        [--trials 100] [--runs 2] [--workers 2 3]

DIR: a folder written by `model.save` (e.g. <run-root>/pixel-image-<hash>/model) or any model spec.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.perception import Perception
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.specs import load_robot, resolve_encoder, resolve_models
from bodyschema.evaluation.levels.benchmark import (
    LevelsConfig,
    evaluate_level,
    measure_levels,
    measure_runs,
)
from bodyschema.evaluation.levels.targets import make_targets


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", required=True, help="the image decoder: a saved-model folder or a spec")
    parser.add_argument("--encoder", required=True, help="the image encoder: a saved-model folder or a spec")
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--runs", type=int, default=2, help="runs of [3] (workers take whole runs)")
    parser.add_argument("--workers", type=int, nargs="+", default=[2], help="process counts compared in [3]")
    return parser.parse_args()


def spec(text: str) -> str:
    return f"trusted:{text}" if Path(text).is_dir() else text


def former_protocol(config, perception, robot, targets, encoder) -> list[dict]:
    """The rows as the levels computed them before: every row on its own, levels 1–2 + encoder as a 2-start
    multi-start (1 screening step, both kept), the guess encoded again for every row."""
    rows = []
    for level in config.levels:
        rows.append(evaluate_level(perception, robot, targets, level, eval_rng(config.seed, 0, "beliefs", level))[0])
        ms = dict(multistart=2, screen_steps=1, keep=2) if level != 3 else {}
        row = evaluate_level(perception, robot, targets, level, eval_rng(config.seed, 0, "beliefs", level),
                             encoder=encoder, **ms)[0]                     # the same μ0 as the row above
        rows.append({**row, "level": f"{level}+enc"})
    return rows


def protocols(config, models, encoder) -> None:
    robot = load_robot(models, config.image_size)
    perception = Perception(models, replace(config.perception, record=False))
    targets = make_targets(robot, config.trials, eval_rng(config.seed, 0, "targets"), True, {},
                           eval_rng(config.seed, 0, "noise"))
    start = time.perf_counter()
    before = former_protocol(config, perception, robot, targets, encoder)
    t_before = time.perf_counter() - start
    start = time.perf_counter()
    after = measure_runs(replace(config, perception=replace(config.perception, record=False)), models, encoder, (0,),
                         robot)[0][0]
    t_after = time.perf_counter() - start
    print(f"[1] protocol, {config.trials} trials, run 0: before {t_before:.1f} s, after {t_after:.1f} s "
          f"(incl. rendering), after/before {t_after / t_before:.2f}")
    print(f"    {'row':7s} {'mean before':>12s} {'after':>8s} {'median before':>14s} {'after':>8s} "
          f"{'evals/trial before':>19s} {'after':>6s}")
    for b, a in zip(before, after):
        print(f"    {a['level']:7s} {b['joint_err_deg']:11.3f}° {a['joint_err_deg']:7.3f}° "
              f"{b['joint_err_median_deg']:13.3f}° {a['joint_err_median_deg']:7.3f}° "
              f"{b['evaluations_per_trial']:19.0f} {a['evaluations_per_trial']:6.0f}")


def decoder_share(model, batch: int) -> None:
    gen = torch.Generator().manual_seed(0)
    low, high = torch.as_tensor(model.body.q_low), torch.as_tensor(model.body.q_high)
    z = (low + (high - low) * torch.rand(batch, len(low), generator=gen, dtype=torch.float64)).float()
    v = torch.rand(batch, *model.output_shape, generator=gen)

    def fused():
        model.predict_and_vjp(z)[1](v)

    calls = {"predict": lambda: model.predict(z), "vjp": lambda: model.vjp(z, v),
             "predict + vjp": lambda: (model.predict(z), model.vjp(z, v)), "predict_and_vjp": fused}
    threads = torch.get_num_threads()
    print(f"[2] decoder at batch {batch}, µs per trial (median of 5 interleaved rounds)")
    for n in (1, 2):
        torch.set_num_threads(n)
        times = {name: [] for name in calls}
        for _ in range(5):
            for name, call in calls.items():
                start = time.perf_counter()
                call()
                times[name].append((time.perf_counter() - start) / batch * 1e6)
        med = {k: float(np.median(t)) for k, t in times.items()}
        print(f"    {n} thread(s): " + ", ".join(f"{k} {t:.0f}" for k, t in med.items()) +
              f"; predict_and_vjp / (predict + vjp) {med['predict_and_vjp'] / med['predict + vjp']:.2f}")
    torch.set_num_threads(threads)


def workers(config, models, counts) -> None:
    base = replace(config, perception=replace(config.perception, record=False), progress=False)
    start = time.perf_counter()
    one = measure_levels(replace(base, workers=1), models)[0].table
    t_one = time.perf_counter() - start
    print(f"[3] {config.runs} runs × {config.trials} trials, {torch.get_num_threads()} torch thread(s): "
          f"1 process {t_one:.1f} s")
    for n in counts:
        start = time.perf_counter()
        table = measure_levels(replace(base, workers=n), models)[0].table
        t = time.perf_counter() - start
        same = all(abs(a["joint_err_deg"] - b["joint_err_deg"]) < 1e-9 for a, b in zip(one, table))
        print(f"    {n} processes {t:.1f} s, /1 process {t / t_one:.2f}; rows equal to 1 process: {same}")


def main() -> None:
    args = arguments()
    config = LevelsConfig(models=(spec(args.model),), encoder=spec(args.encoder), trials=args.trials, runs=args.runs,
                          multistart=0, mlflow=False, plots=False, progress=False)
    models = resolve_models(config.models, (), None, None)
    encoder = resolve_encoder(config.encoder, load_robot(models, config.image_size))
    protocols(config, models, encoder)
    decoder_share(next(m for m in models if m.modality == "image"), args.trials)
    workers(config, models, args.workers)


if __name__ == "__main__":
    main()
