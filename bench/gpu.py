"""The per-call costs of issue 36's table on "cpu", and on "cuda" where torch sees one (a script, not a test).

Rows, per device: a decoder epoch at batch 64 and 512 (a small pixel decoder of planar2's camera; on cuda the
training loop's device rule makes batch 64 a 512, `models/_nn_device.py`, and the row says so), the levels'
inference of --trials trials at once (adam+lm, ms per round: wall / the rounds the batch ran), one tracker frame of
--trials streams, and the levels benchmark of 5 runs × --trials (levels 1–3 and the floor, targets rendered) with its
runs apart and in one batch (evaluation/levels/run_batch.py). Then, on the CPU, the levels' descent (Adam, then LM)
before/after its batched checks (aif/descent.py, check_every; d78a013: Adam's, 00ac2f9: LM's): the former
descent.py read from git (--before), both on the same targets in this run, with the largest belief change.

    MUJOCO_GL=egl OMP_NUM_THREADS=1 .venv/bin/python bench/gpu.py [--trials 500] [--before 00ac2f9] [--repeats 3]

Without a GPU it prints "cuda: not available on this machine": the CUDA rows (and CUDA graphs / torch.compile of the
fixed-shape step, which pay only where kernel launches dominate) need one.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
import types
from dataclasses import replace

import numpy as np
import torch

from bodyschema.aif import descent
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import LMSettings, PerceptionConfig
from bodyschema.aif.tracker import Tracker
from bodyschema.aif.tracker_config import TrackerConfig
from bodyschema.datagen.body.robot import Robot
from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels
from bodyschema.models._nn_device import plan_for
from bodyschema.models.pixel import PixelDecoder
from bodyschema.models.scaling import BodySpec

LEVEL_RUNS = 5                      # issue 36's target: 5 × 500 levels trials


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=500)
    parser.add_argument("--poses", type=int, default=2048, help="training poses of the decoder epoch")
    parser.add_argument("--before", default="00ac2f9", help="the commit whose aif/descent.py is the 'before'")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved rounds of before/after (min taken)")
    return parser.parse_args()


def data(n: int):
    with Robot.load("planar2", image_size=(16, 16)) as robot:
        q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(n, 2))
        images = torch.from_numpy(robot.observe(q)["image"]).float() / 255.0
        body = BodySpec(robot.name, robot.joint_names, *map(tuple, robot.sampling_ranges.T))
    return body, torch.from_numpy(q), images


def decoder(body, batch_size=32, epochs=3):
    return PixelDecoder(body, "image", (16, 16), fc_hidden=16, channels=(8, 4), epochs=epochs, batch_size=batch_size)


def timed(call):
    start = time.perf_counter()
    out = call()
    return time.perf_counter() - start, out


def device_rows(device: str, body, q, images, model, trials: int) -> None:
    for batch in (64, 512):
        t, _ = timed(lambda batch=batch: decoder(body, batch, 1).fit(q.float(), images, progress=False, device=device))
        ruled = plan_for(torch.device(device), batch).batch_size       # cuda: the device rule's batch
        shown = f"batch {batch}" + (f" (the cuda rule's {ruled})" if ruled != batch else "")
        print(f"    {device}: decoder epoch, {len(q)} poses, {shown}: {t * 1e3:.0f} ms")
    model.to(device)
    obs, mu0 = {"image": images[:trials]}, q[:trials] + 0.1
    perception = Perception([model], PerceptionConfig(record=False))
    perception.infer(obs, mu0)                                             # warm-up
    t, r = timed(lambda p=perception: p.infer(obs, mu0))
    rounds = int(r.steps.max())
    print(f"    {device}: levels, {trials} trials: {t:.2f} s, {rounds} rounds, {t / rounds * 1e3:.1f} ms per round")
    tracker = Tracker([model], TrackerConfig())
    frame = {"image": images[:trials]}
    tracker.reset(q[:trials])
    tracker.step(frame, dt=1 / 30)
    t, _ = timed(lambda: tracker.step(frame, dt=1 / 30))
    print(f"    {device}: tracker frame, {trials} streams: {t * 1e3:.1f} ms")
    for per_batch in (1, LEVEL_RUNS):                                       # the runs apart, then in one batch
        config = LevelsConfig(trials=trials, runs=LEVEL_RUNS, multistart=0, run_batch=per_batch, device=device,
                              mlflow=False, plots=False, progress=False,
                              perception=replace(LevelsConfig().perception, record=False))
        t, _ = timed(lambda c=config: measure_levels(c, [model]))
        print(f"    {device}: levels benchmark, {LEVEL_RUNS} × {trials} trials, levels 1–3 + floor, {per_batch} "
              f"run(s) per batch: {t:.1f} s")
    model.to("cpu")


def former_descent(commit: str) -> types.ModuleType:
    source = subprocess.run(["git", "show", f"{commit}:aif/descent.py"], capture_output=True, text=True, check=True)
    module = types.ModuleType("former_descent")
    sys.modules[module.__name__] = module                                  # dataclasses look their module up
    exec(compile(source.stdout, f"{commit}:aif/descent.py", "exec"), module.__dict__)
    return module


def before_after(model, q, images, trials: int, commit: str, repeats: int) -> None:
    """The levels' inference (adam+lm) with `commit`'s descent.py and with today's, K = 1 and 4, on the same targets."""
    former, names = former_descent(commit), ("adam", "levenberg_marquardt", "adam_then_lm")
    current = {name: getattr(descent, name) for name in names}
    plain = former.adam_then_lm

    def before(*args, check_every=1, **kwargs):                           # run at K = 1, the former's default
        return plain(*args, **kwargs)

    former.adam_then_lm = before
    obs, mu0 = {"image": images[:trials]}, q[:trials] + 0.1
    runs = {"before": (former, 1, False), "after K=1": (None, 1, False), "K=1 + trial derivatives": (None, 1, True),
            "after K=4": (None, 4, False)}
    times, results = {name: [] for name in runs}, {}
    try:
        for _ in range(repeats):
            for name, (module, k, derivatives) in runs.items():
                for function in names:
                    setattr(descent, function, getattr(module, function) if module else current[function])
                config = PerceptionConfig(record=False, check_every=k, lm=LMSettings(trial_derivatives=derivatives))
                perception = Perception([model], config)
                t, results[name] = timed(lambda p=perception: p.infer(obs, mu0))
                times[name].append(t)
    finally:
        for function in names:
            setattr(descent, function, current[function])
    base = results["before"]
    rounds = int(base.steps.max())
    print(f"[2] cpu, levels' inference (adam+lm) of {trials} trials, {rounds} rounds, before = {commit}'s descent.py "
          f"(at its defaults), min of {repeats} interleaved runs")
    for name, r in results.items():
        t = min(times[name])
        print(f"    {name:24s} {t / rounds * 1e3:6.2f} ms per round, /before {t / min(times['before']):.2f}; "
              f"steps equal {torch.equal(r.steps, base.steps)}, converged equal "
              f"{torch.equal(r.converged, base.converged)}, max |Δμ| {float((r.mu - base.mu).abs().max()):.1e} rad")


def main() -> None:
    args = arguments()
    torch.manual_seed(0)
    body, q, images = data(args.poses + args.trials)
    model = decoder(body).fit(q[:args.poses].float(), images[:args.poses], progress=False)
    test_q, test_images = q[args.poses:], images[args.poses:]
    print(f"[1] issue 36's rows, {torch.get_num_threads()} torch thread(s)")
    device_rows("cpu", body, q[:args.poses], images[:args.poses], model, args.trials)
    if torch.cuda.is_available():
        device_rows("cuda", body, q[:args.poses], images[:args.poses], model, args.trials)
    else:
        print("    cuda: not available on this machine (the cuda rows, and CUDA graphs / torch.compile of the step, "
              "need one)")
    before_after(model, test_q, test_images, args.trials, args.before, args.repeats)


if __name__ == "__main__":
    main()
