"""The probe's concurrency cases: two writers, one target, run as real `bodyschema` processes at several offsets.

    .venv/bin/python bench/probe_races.py [--offsets 0 0.3 1.0] [--only SUBSTRING]

Each case starts writer A, waits an offset (s), starts writer B on the same target, waits for both and judges:
  safe      the target holds one writer's whole result (it validates) and every other writer either succeeded on a
            target of its own (a run folder, a registry version) or was refused with the house line
  lost      two writers both exited 0 for one target that only one may hold: one result silently replaced
  invalid   the target is left in a state that `bodyschema validate` (or the format's reader) rejects
  unclear   a writer failed without the house line, or with a traceback
Also run by `bench/probe.py` after the bad-input cases. Not a test: tests/reliability/ asserts each race in-process;
this is the figure the reliability reports quote ("concurrency: N cases → nothing lost").
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from probe_tally import last_line, print_tally  # noqa: E402 — beside this file

OUTCOMES = ("safe", "lost", "invalid", "unclear")
SMALL = "--robot planar2 --n 48 --no-images --quiet"
IMPORT = "--angles deg --robot planar2 --quiet"


@dataclass(frozen=True)
class Race:
    """Two commands ({W}: the scratch folder) and what must hold after both ended."""
    name: str
    first: str
    second: str
    target: str                 # the path both write, relative to {W}
    one_winner: bool = True     # only one may succeed (a new store/file); False: both own results must survive
    check: str = "store"        # "store": validate; "hdf5": h5py opens it; "runs": count run folders; "registry"


RACES = [
    Race("import-import, two sources", f"import {{W}}/rec_a {IMPORT} --out {{W}}/out.zarr",
         f"import {{W}}/rec_b {IMPORT} --out {{W}}/out.zarr", "out.zarr"),
    Race("import-import, one source", f"import {{W}}/rec_a {IMPORT} --out {{W}}/out.zarr",
         f"import {{W}}/rec_a {IMPORT} --out {{W}}/out.zarr", "out.zarr"),
    Race("import-datagen", f"import {{W}}/rec_a {IMPORT} --out {{W}}/out.zarr",
         f"datagen {SMALL} --out {{W}}/out.zarr", "out.zarr"),
    Race("datagen-import", f"datagen {SMALL} --out {{W}}/out.zarr",
         f"import {{W}}/rec_a {IMPORT} --out {{W}}/out.zarr", "out.zarr"),
    Race("datagen-datagen", f"datagen {SMALL} --seed 1 --out {{W}}/out.zarr",
         f"datagen {SMALL} --seed 2 --out {{W}}/out.zarr", "out.zarr"),
    Race("export-export hdf5", "export dataset {W}/good.zarr {W}/out.h5 --to hdf5",
         "export dataset {W}/good.zarr {W}/out.h5 --to hdf5", "out.h5", check="hdf5"),
    Race("export-export lerobot", "export dataset {W}/good.zarr {W}/out_lr --to lerobot",
         "export dataset {W}/good.zarr {W}/out_lr --to lerobot", "out_lr", check="lerobot"),
    Race("levels-levels, one --out", "evaluate levels --model analytic:planar2:ee_xyz --trials 2 --runs 1 --levels 1 "
         "--no-mlflow --no-plots --no-progress --out {W}/res",
         "evaluate levels --model analytic:planar2:ee_xyz --trials 2 --runs 1 --levels 1 --no-mlflow --no-plots "
         "--no-progress --out {W}/res", "res", one_winner=False, check="runs"),
    Race("train-train, one registry", "train gpr --data {W}/good.zarr --no-progress --tracking-uri "
         "sqlite:///{W}/mlflow.db --run-root {W}/runs",
         "train gpr --data {W}/good.zarr --no-progress --tracking-uri sqlite:///{W}/mlflow.db --run-root {W}/runs",
         "mlflow.db", one_winner=False, check="registry"),
]


def make_world(w: Path) -> Path:
    """Two recordings (rec_a, rec_b) and a valid store (good.zarr)."""
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate
    from tests.datagen.import_sources import planar2_frames, write_folder

    for name, seed in (("rec_a", 0), ("rec_b", 1)):
        q, images = planar2_frames(6, seed=seed)
        write_folder(w / name, q, images)
    generate(DatagenConfig(robot="planar2", n=48, images=False, out=w / "good.zarr"), progress=False)
    return w


def start(world: Path, command: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG", "RAY_ADDRESS")}
    env.setdefault("MUJOCO_GL", "egl")
    argv = [sys.executable, "-m", "bodyschema.cli", *command.format(W=world).split()]
    return subprocess.Popen(argv, cwd=world, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def judge(race: Race, world: Path, codes: list[int], errors: list[str]) -> str:
    failed = [err for code, err in zip(codes, errors) if code != 0]
    if any("Traceback" in err or " must be " not in err for err in failed):
        return "unclear"
    if not target_holds(race, world):
        return "invalid"
    if race.one_winner:
        return "safe" if codes.count(0) == 1 else "lost"
    return "safe" if results_kept(race, world) == codes.count(0) else "lost"


def target_holds(race: Race, world: Path) -> bool:
    target = world / race.target
    if race.check == "store":
        done = subprocess.run([sys.executable, "-m", "bodyschema.cli", "validate", str(target)], cwd=world,
                              capture_output=True, text=True)
        return done.returncode == 0
    if race.check == "hdf5":
        import h5py
        try:
            with h5py.File(target, "r") as f:
                return "q" in f
        except OSError:
            return False
    if race.check == "lerobot":
        try:
            return "features" in json.loads((target / "meta" / "info.json").read_text())
        except (OSError, ValueError):
            return False
    return True


def results_kept(race: Race, world: Path) -> int:
    """How many writers' results survive on a shared target: run folders, or registered versions."""
    if race.check == "runs":
        folder = world / race.target
        return sum(1 for p in folder.iterdir() if p.is_dir() and not p.is_symlink()) if folder.is_dir() else 0
    from mlflow import MlflowClient
    client = MlflowClient(f"sqlite:///{world / 'mlflow.db'}")
    return sum(len(client.search_model_versions(f"name='{m.name}'")) for m in client.search_registered_models())


def run_race(race: Race, template: Path, offset: float) -> tuple[str, list[str]]:
    with tempfile.TemporaryDirectory() as scratch:
        world = Path(scratch) / "w"
        shutil.copytree(template, world)
        first = start(world, race.first)
        time.sleep(offset)
        second = start(world, race.second)
        outs = [p.communicate() for p in (first, second)]
        codes, errors = [first.returncode, second.returncode], [err for _, err in outs]
        return judge(race, world, codes, errors), errors


def main(argv: list[str] | None = None) -> Counter:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--offsets", type=float, nargs="+", default=[0.0, 0.3, 1.0], help="s between the starts")
    parser.add_argument("--only", default="", help="run only the races whose name contains this")
    args = parser.parse_args(argv)
    tally, odd, total = Counter(), [], 0
    with tempfile.TemporaryDirectory() as scratch:
        template = make_world(Path(scratch))
        for race in (r for r in RACES if args.only in r.name):
            for offset in args.offsets:
                outcome, errors = run_race(race, template, offset)
                tally[outcome] += 1
                total += 1
                print(f"[race {total}] {outcome:<8} {race.name} (+{offset:g} s)", file=sys.stderr, flush=True)
                if outcome != "safe":
                    tails = [last_line(e, width=160) for e in errors]
                    odd.append(f"- {race.name} (+{offset:g} s, {outcome}): {tails}")
    print_tally("concurrency", tally, OUTCOMES, odd)
    return tally


if __name__ == "__main__":
    main()
