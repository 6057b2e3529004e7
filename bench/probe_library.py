"""The probe's library cases: bad input through the Python entry points a user calls without our CLI (Gymnasium's
`gymnasium.make` on the reaching environments), each run as `python -c` in a scratch folder of robot records.

    .venv/bin/python bench/probe_library.py [--only SUBSTRING]

A library call answers bad input by raising; the outcome is judged by that exception's last line:
  clear error         the raised message holds the house line (" must be ")
  traceback           another exception (a KeyError, a TypeError from deep inside), or the process died of a signal
  silently accepted   the call returned
Also run by `bench/probe.py` after the CLI cases.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

from probe_tally import last_line, print_tally

OUTCOMES = ("clear error", "traceback", "silently accepted")
GENERIC = '"bodyschema/Reach-v0", robot="{W}/rec.toml"'
MAKE = "import gymnasium, bodyschema.envs; gymnasium.make({args}).reset(seed=0)"

# (id, gymnasium.make arguments, the keys and [tables] that replace planar2's own in its record, None: no record)
CASES = [
    ("env-id-robot-mismatch", '"bodyschema/Reach-nao_arm-v0", robot="panda"', None),
    ("env-robot-unknown", '"bodyschema/Reach-v0", robot="mars"', None),
    ("env-record-hold-number", '"bodyschema/Reach-v0", robot="{W}/rec.toml"', "hold = 5\n"),
    ("env-record-joints-number", '"bodyschema/Reach-v0", robot="{W}/rec.toml"', "joints = 5\n"),
    ("env-record-joints-string", '"bodyschema/Reach-v0", robot="{W}/rec.toml"', 'joints = "j1"\n'),
    ("env-record-workspace-flat", '"bodyschema/Reach-v0", robot="{W}/rec.toml"',
     "[workspaces]\nfull = [1.0, 2.0]\ncamera = [[-2.5, 2.5], [-2.5, 2.5]]\n"),
    ("env-record-duration-negative", '"bodyschema/Reach-v0", robot="{W}/rec.toml"',
     "[reaching]\nduration_s = -1.0\n"),
    ("env-record-mesh-dir-number", '"bodyschema/Reach-v0", robot="{W}/rec.toml"', "mesh_dir = 5\n"),
    ("env-record-ee-world", '"bodyschema/Reach-v0", robot="{W}/rec.toml"', '[ee]\nbody = "world"\n'),
]


def record(world: Path, edit: str) -> None:
    """planar2's record under a name of its own (a copy may not take the shipped name), its model copied beside it,
    and `edit` replacing the table (or key) it names."""
    import tomllib
    from importlib.resources import files

    from bodyschema.datagen.body.record import dumps_toml

    robots = files("bodyschema.datagen") / "robots"
    (world / "planar2.xml").write_text((robots / "planar2.xml").read_text())
    base = {**tomllib.loads((robots / "planar2.toml").read_text()), "name": "rec"}
    base.update(tomllib.loads(edit))
    (world / "rec.toml").write_text(dumps_toml(base))


def classify(done: subprocess.CompletedProcess | None) -> str:
    if done is None or done.returncode < 0:
        return "traceback"
    if done.returncode == 0:
        return "silently accepted"
    last = last_line(done.stderr, width=10_000)
    return "clear error" if " must be " in last else "traceback"


def run_case(world: Path, arguments: str, edit: str | None, timeout: float = 120.0):
    if edit is not None:
        record(world, edit)
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    code = MAKE.format(args=arguments.format(W=world))
    try:
        return subprocess.run([sys.executable, "-c", code], cwd=world, env=env, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return None


def main(argv: list[str] | None = None) -> Counter:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="", help="run only the cases whose id contains this")
    args = parser.parse_args(argv)
    tally, odd = Counter(), []
    with tempfile.TemporaryDirectory() as scratch:
        control = run_case(Path(scratch), GENERIC, "")
        if control is None or control.returncode != 0:       # else every case would fail for that one reason
            raise SystemExit("the unedited record must build an environment. Got: "
                             f"{'a hang' if control is None else last_line(control.stderr)}")
        for case_id, arguments, edit in (c for c in CASES if args.only in c[0]):
            done = run_case(Path(scratch), arguments, edit)
            outcome = classify(done)
            tally[outcome] += 1
            print(f"[library] {outcome:<17} {case_id}", file=sys.stderr, flush=True)
            if outcome != "clear error":
                tail = "hang" if done is None else last_line(done.stderr)
                odd.append(f"- {case_id} ({outcome}): gymnasium.make({arguments}) {edit or ''!r} → {tail}")
    print_tally("library calls", tally, OUTCOMES, odd)
    return tally


if __name__ == "__main__":
    main()
