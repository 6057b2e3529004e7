"""torch threads on a busy machine: the demo's decoder epoch and a levels batch at 1 and N threads, as the machine is
vs beside a CPU hog (a script, not a test; issue 36).

Prints, measured side by side in one run, each figure from a fresh process (OpenMP reads its wait policy at start):
  * the pixel decoder's training epoch (the demo's: lean, batch 16, 1638 images of 56×80; `--steps` minibatches
    timed and scaled to the epoch), seconds;
  * a levels batch: `--evals` decoder evaluations (predict_and_jacobian, then predict_and_vjp and its VJP: a
    Gauss–Newton and a gradient step) at the demo's 30 pixel trials, scaled to 100 (about a level row's), seconds;
at 1 thread, at N threads (torch's default count), and at N with OMP_WAIT_POLICY=PASSIVE (waiting threads sleep
instead of spinning); first on the machine as it is (its load average printed), then with a hog beside: one
`while True: pass` process per core. Ratios are N / 1 thread and hog / as-is. Last, what `bodyschema.threads`
chooses in each condition and what its measurement cost.

    MUJOCO_GL=egl .venv/bin/python bench/busy.py [--steps 8] [--evals 3] [--threads N]

About 1–2 min on 2 loaded cores. "As it is" is not idle on a shared machine: read its load average.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

IMAGES, BATCH, TRIALS, ROW_EVALS = 1638, 16, 30, 100     # the demo's decoder fit and pixel levels (bodyschema/demo.py)
CONFIGS = (("1 thread", 1, False), ("N threads", None, False), ("N, passive wait", None, True))


def child(what: str, threads: int, steps: int, evals: int) -> dict:
    """In a fresh process: the epoch and the levels batch at `threads` threads. → seconds of each (scaled)."""
    import torch

    from bodyschema.models.pixel import PixelDecoder
    from bodyschema.models.scaling import BodySpec

    torch.set_num_threads(threads)
    body = BodySpec("bench", tuple(f"j{i}" for i in range(5)), (-1.0,) * 5, (1.0,) * 5)
    gen = torch.Generator().manual_seed(0)
    q = torch.rand(steps * BATCH, 5, generator=gen) * 2 - 1                       # (N, 5) rad
    x = torch.rand(steps * BATCH, 56, 80, generator=gen)                          # (N, 56, 80) in [0, 1]
    model = PixelDecoder(body, "image", (56, 80), epochs=1, batch_size=BATCH)
    model.fit(q[:2 * BATCH], x[:2 * BATCH])                                       # warm-up: oneDNN primitives
    epoch = []
    model.fit(q, x, on_epoch=lambda _, m: epoch.append(m["epoch_seconds"]))
    z = q[:TRIALS].double() * 0.5                                                 # (30, 5) rad
    v = torch.rand(TRIALS, 56, 80, generator=gen, dtype=torch.float64)
    model.predict_and_jacobian(z)
    start = time.perf_counter()
    for _ in range(evals):
        model.predict_and_jacobian(z)
        model.predict_and_vjp(z)[1](v)
    batch = (time.perf_counter() - start) / (2 * evals) * ROW_EVALS
    return {"epoch_s": epoch[0] * IMAGES / (steps * BATCH), "levels_s": batch}


def policy_child() -> dict:
    """What the thread policy chooses here, now, and what choosing cost."""
    import torch

    from bodyschema import threads

    default = torch.get_num_threads()
    start = time.perf_counter()
    choice = threads.choose()
    return {"threads": choice.threads, "of": default, "cost_s": time.perf_counter() - start,
            "seconds": {str(k): v for k, v in (choice.seconds or {}).items()}}


def spawn(args: list[str], passive: bool = False) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                                            "BODYSCHEMA_THREADS", "OMP_WAIT_POLICY")}
    if passive:
        env["OMP_WAIT_POLICY"] = "PASSIVE"
    out = subprocess.run([sys.executable, __file__, *args], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure(label: str, n: int, steps: int, evals: int) -> dict:
    print(f"-- {label} (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)", flush=True)
    rows = {}
    for name, threads, passive in CONFIGS:
        rows[name] = spawn(["--child", "run", "--threads", str(threads or n), "--steps", str(steps),
                            "--evals", str(evals)], passive)
        print(f"   {name:16s} epoch {rows[name]['epoch_s']:6.1f} s   levels batch {rows[name]['levels_s']:6.2f} s",
              flush=True)
    rows["policy"] = spawn(["--child", "policy"])
    p = rows["policy"]
    print(f"   policy chooses {p['threads']} of {p['of']} (measured {p['seconds']} s per step; "
          f"choosing took {p['cost_s']:.2f} s)", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=8, help="decoder minibatches timed (scaled to the epoch)")
    parser.add_argument("--evals", type=int, default=3, help="decoder evaluation pairs timed (scaled to 100)")
    parser.add_argument("--threads", type=int, default=os.cpu_count(), help="N (default: one per core)")
    parser.add_argument("--child", choices=("run", "policy"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child == "run":
        print(json.dumps(child("run", args.threads, args.steps, args.evals)))
        return
    if args.child == "policy":
        print(json.dumps(policy_child()))
        return
    started = time.perf_counter()
    as_is = measure("as it is", args.threads, args.steps, args.evals)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 1)]
    try:
        time.sleep(1.0)
        hog = measure(f"with a hog on every core ({len(hogs)} spinning processes)", args.threads, args.steps,
                      args.evals)
    finally:
        for p in hogs:
            p.kill()
            p.wait()
    print(f"\nratios (N = {args.threads}):")
    for what in ("epoch_s", "levels_s"):
        for label, rows in (("as is", as_is), ("hog", hog)):
            one = rows["1 thread"][what]
            print(f"   {what[:-2]:7s} {label:6s}  N/1 {rows['N threads'][what] / one:5.2f}   "
                  f"N passive/1 {rows['N, passive wait'][what] / one:5.2f}")
        for name, _, _ in CONFIGS:
            print(f"   {what[:-2]:7s} {name:16s} hog/as-is {hog[name][what] / as_is[name][what]:5.2f}")
    print(f"total {time.perf_counter() - started:.0f} s")


if __name__ == "__main__":
    main()
