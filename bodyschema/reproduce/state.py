"""A reproduce run's folder and its `state.json`: which recipes it runs and, per finished step, the command it ran,
its product and its seconds. A step is recorded only once it finished, by an atomic rename, so a killed run
continues at the first step without a record (datagen and train resume their own shards and checkpoints within).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.evaluation.core import runs

STATE = "state.json"


def new_run(config, recipes: list[str]) -> tuple[Path, dict]:
    """A fresh `<config.out>/<run-id>/` (the benchmarks' run folders: UTC start and config hash, run.json) with its
    state."""
    folder = runs.new_run(config)
    state = {"recipes": recipes, "started": time.time(), "steps": {}, "finished": None}
    save(folder, state)
    return folder, state


def load(folder: Path) -> dict:
    path = Path(folder) / STATE
    if not path.is_file():
        raise FileNotFoundError(must_be("--run-id", "a reproduce run folder holding state.json", str(folder),
                                        "List the runs with `ls results/reproduce` (or your --out)."))
    return json.loads(path.read_text())


def save(folder: Path, state: dict) -> None:
    path = Path(folder) / STATE
    tmp = path.with_name(f".{STATE}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(state, indent=1, default=str) + "\n")
    tmp.replace(path)


def unfinished(out: Path, recipes: list[str]) -> Path | None:
    """The newest run under `out` of exactly these recipes that has not finished, else None."""
    runs = sorted(p for p in Path(out).glob("*/" + STATE)) if Path(out).is_dir() else []
    for path in reversed(runs):
        state = json.loads(path.read_text())
        if state.get("recipes") == recipes and not state.get("finished"):
            return path.parent
    return None
