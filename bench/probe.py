"""The bad-input probe's tally: every fuzz case of the test suite run as a user would, through the console script.

    .venv/bin/python bench/probe.py [--timeout 120] [--only SUBSTRING] [--no-library] [--no-races]

Gathers the one-line bad-input cases of `tests/test_cli_fuzz.py` and of every `tests/reliability/test_*.py` (its
module-level `CASES…` lists of (id, command) or (id, command, env)), builds each module's scratch folder (its
`make_world(folder)`, else the fuzz test's `build_world`: a valid store, damaged stores, crafted model folders), runs
each case as a real `bodyschema` process in it and sorts the
outcome into one of:
  clear error     exit 1–2, the house line (" must be ") or tyro's parse message, no traceback, nothing written
  traceback       a Python traceback reached the user, or the process died of a signal (a segfault)
  hang            still running after --timeout seconds (killed)
  half-written    refused, but a file of the folder was added, removed or changed
  silently accepted   exit 0
  unclear         refused without a traceback, but with no house line
Prints the counts and the cases that are not clear errors, then the library calls' tally (bench/probe_library.py:
`gymnasium.make` on bad robot records) and the concurrency tally (bench/probe_races.py: two writers, one target, as
real processes at several offsets; a few minutes). Not a test: the suite asserts each case in-process; this
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

import probe_library  # noqa: E402 — beside this file
import probe_races  # noqa: E402
from probe_tally import last_line, print_tally  # noqa: E402

from tests.test_cli_fuzz import TYRO_PHRASES, VALIDATE_ANSWERS, build_world, snapshot  # noqa: E402 — after the repo root is on sys.path

OUTCOMES = ("clear error", "traceback", "hang", "half-written", "silently accepted", "unclear")


def case_modules() -> list:
    """The fuzz test and every reliability test module that lists one-line cases."""
    names = ["tests.test_cli_fuzz"] + [f"tests.reliability.{p.stem}"
                                       for p in sorted((REPO / "tests" / "reliability").glob("test_*.py"))]
    modules = [importlib.import_module(name) for name in names]
    return [m for m in modules if module_cases(m)]


def module_cases(module) -> list[tuple[str, str, dict[str, str]]]:
    """Every (id, command, env) of a module's CASES, CASES_WITH_… lists."""
    lists = [value for name, value in vars(module).items() if name.startswith("CASES") and isinstance(value, list)]
    return [(case[0], case[1], case[2] if len(case) > 2 else {}) for cases in lists for case in cases]


def classify(case_id: str, done: subprocess.CompletedProcess | None, changed: bool, validate_answers: set) -> str:
    if done is None:
        return "hang"
    if "Traceback" in done.stderr or done.returncode < 0:
        return "traceback"
    if done.returncode == 0:
        return "silently accepted"
    if changed:
        return "half-written"
    clear = " must be " in done.stderr or any(p in done.stderr for p in TYRO_PHRASES)
    allowed = {1, 2} if case_id in validate_answers else {2}   # exit 1: validate's "this store has problems"
    return "clear error" if clear and done.returncode in allowed else "unclear"


def run_case(world: Path, command: str, env: dict[str, str], timeout: float) -> tuple[object, bool]:
    before = snapshot(world)
    unset = ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG", "RAY_ADDRESS")
    full_env = {k: v for k, v in os.environ.items() if k not in unset}
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
    parser.add_argument("--library", action=argparse.BooleanOptionalAction, default=True,
                        help="also the library calls (bench/probe_library.py)")
    parser.add_argument("--races", action=argparse.BooleanOptionalAction, default=True,
                        help="also the concurrency cases (bench/probe_races.py)")
    args = parser.parse_args()
    tally, odd, total = Counter(), [], 0
    for module in case_modules():
        cases = [c for c in module_cases(module) if args.only in c[0]]
        if not cases:
            continue
        with tempfile.TemporaryDirectory() as scratch:
            world = getattr(module, "make_world", build_world)(Path(scratch))   # the module's own scratch folder
            for case_id, command, env in cases:
                done, changed = run_case(world, command, env, args.timeout)
                answers = VALIDATE_ANSWERS | getattr(module, "VALIDATE_ANSWERS", set())
                outcome = classify(case_id, done, changed, answers)
                tally[outcome] += 1
                total += 1
                print(f"[{total}] {outcome:<17} {module.__name__.split('.')[-1]}: {case_id}", file=sys.stderr,
                      flush=True)
                if outcome != "clear error":
                    tail = "" if done is None else last_line(done.stderr)
                    odd.append(f"- {case_id} ({outcome}): `{command}` {env or ''} → {tail}")
    print_tally("bad inputs", tally, OUTCOMES, odd)
    only = ["--only", args.only] if args.only else []
    if args.library:
        probe_library.main(only)
    if args.races:
        probe_races.main(only)


if __name__ == "__main__":
    main()
