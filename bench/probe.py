"""The bad-input probe's tally: every fuzz case of the test suite run as a user would, through the console script.

    .venv/bin/python bench/probe.py [--timeout 120] [--only SUBSTRING]

Gathers the one-line bad-input cases of `tests/test_cli_fuzz.py` and of every `tests/reliability/test_*.py` that
has a module-level `CASES` list ((id, command) or (id, command, env)), builds the fuzz scratch folder once (a valid
store, damaged stores, crafted model folders), runs each case as a real `bodyschema` process in it and sorts the
outcome into one of:
  clear error     exit 1–2, the house line (" must be ") or tyro's parse message, no traceback, nothing written
  traceback       a Python traceback reached the user, or the process died of a signal (a segfault)
  hang            still running after --timeout seconds (killed)
  half-written    refused, but a file of the folder was added, removed or changed
  silently accepted   exit 0
  unclear         refused without a traceback, but with no house line
Prints the counts and the cases that are not clear errors. Not a test: the suite asserts each case in-process; this
is the figure of the reliability reports (bad inputs / clear errors / tracebacks / hangs / half-written / silently
accepted), measured the way the probe measured it.
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.test_cli_fuzz import TYRO_PHRASES, VALIDATE_ANSWERS, build_world, snapshot  # noqa: E402

OUTCOMES = ("clear error", "traceback", "hang", "half-written", "silently accepted", "unclear")


def gather_cases() -> list[tuple[str, str, dict[str, str]]]:
    """Every (id, command, env) of the fuzz test and the reliability tests."""
    modules = ["tests.test_cli_fuzz"] + [f"tests.reliability.{p.stem}"
                                         for p in sorted((REPO / "tests" / "reliability").glob("test_*.py"))]
    cases = []
    for name in modules:
        for case in getattr(importlib.import_module(name), "CASES", []):
            cases.append((case[0], case[1], case[2] if len(case) > 2 else {}))
    return cases


def classify(case_id: str, done: subprocess.CompletedProcess | None, changed: bool) -> str:
    if done is None:
        return "hang"
    if "Traceback" in done.stderr or done.returncode < 0:
        return "traceback"
    if done.returncode == 0:
        return "silently accepted"
    if changed:
        return "half-written"
    clear = " must be " in done.stderr or any(p in done.stderr for p in TYRO_PHRASES)
    allowed = {1, 2} if case_id in VALIDATE_ANSWERS else {2}
    return "clear error" if clear and done.returncode in allowed else "unclear"


def run_case(world: Path, command: str, env: dict[str, str], timeout: float) -> tuple[object, bool]:
    before = snapshot(world)
    full_env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG")}
    full_env.update({"MUJOCO_GL": full_env.get("MUJOCO_GL", "egl"), **env})
    argv = [sys.executable, "-m", "bodyschema.cli", *command.format(W=world).split()]
    try:
        done = subprocess.run(argv, cwd=world, env=full_env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        done = None
    return done, snapshot(world) != before


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds before a case counts as a hang")
    parser.add_argument("--only", default="", help="run only the cases whose id contains this")
    args = parser.parse_args()
    cases = [c for c in gather_cases() if args.only in c[0]]
    tally, odd = Counter(), []
    with tempfile.TemporaryDirectory() as scratch:
        world = build_world(Path(scratch))
        for i, (case_id, command, env) in enumerate(cases, 1):
            done, changed = run_case(world, command, env, args.timeout)
            outcome = classify(case_id, done, changed)
            tally[outcome] += 1
            print(f"[{i}/{len(cases)}] {outcome:<17} {case_id}", file=sys.stderr, flush=True)
            if outcome != "clear error":
                tail = "" if done is None else (done.stderr.strip().splitlines() or [""])[-1][:200]
                odd.append(f"- {case_id} ({outcome}): `{command}` {env or ''} → {tail}")
    print(f"bad inputs {len(cases)}: " + " / ".join(f"{name} {tally[name]}" for name in OUTCOMES))
    print("\n".join(odd))


if __name__ == "__main__":
    main()
