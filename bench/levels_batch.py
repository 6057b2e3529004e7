"""Levels runs inferred one at a time or all in one batch (`--run-batch`), side by side (a script, not a test).

For each model spec: `measure_levels` of --runs × --trials on the same targets with run_batch 1 and run_batch = runs,
one process, the wall time of each, their ratio, and the largest difference between the two's rows (mean joint error,
deg) with the floor's. The rows differ only by the rounding of a larger batch (evaluation/levels/run_batch.py).

    MUJOCO_GL=egl OMP_NUM_THREADS=1 .venv/bin/python bench/levels_batch.py analytic:nao_arm:ee_xyz DIR ... \
        [--trials 500] [--runs 5] [--levels 1 2 3]

DIR: a folder written by `model.save` (e.g. <run-root>/gpr-ee_xyz-<hash>/model) or any model spec.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import torch

from bodyschema.evaluation.core.specs import resolve_models
from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", help="model specs or saved-model folders, each benchmarked alone")
    parser.add_argument("--trials", type=int, default=500)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    return parser.parse_args()


def timed(config: LevelsConfig, models) -> tuple[float, list[dict]]:
    start = time.perf_counter()
    summary = measure_levels(config, models)[0]
    return time.perf_counter() - start, summary.floor_rows + summary.rows


def main() -> None:
    args = arguments()
    print(f"{args.runs} runs × {args.trials} trials, levels {args.levels}, {torch.get_num_threads()} torch thread(s)")
    print(f"{'model':44s} {'one at a time':>14s} {'one batch':>10s} {'speed-up':>9s} {'max |Δ row| (deg)':>18s}")
    for text in args.models:
        spec = f"trusted:{text}" if Path(text).is_dir() else text
        config = LevelsConfig(models=(spec,), trials=args.trials, runs=args.runs, levels=tuple(args.levels),
                              mlflow=False, plots=False, progress=False)
        config = replace(config, perception=replace(config.perception, record=False))
        models = resolve_models(config.models, (), None, None)
        apart, rows_apart = timed(replace(config, run_batch=1), models)
        together, rows_together = timed(replace(config, run_batch=args.runs), models)
        delta = max(abs(a["joint_err_deg"] - b["joint_err_deg"]) for a, b in zip(rows_apart, rows_together))
        print(f"{text[-44:]:44s} {apart:13.1f}s {together:9.1f}s {apart / together:8.2f}× {delta:18.2e}")


if __name__ == "__main__":
    main()
