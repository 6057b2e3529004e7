"""`bodyschema reproduce`'s flags (light: the CLI imports this at start-up)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.reproduce.recipes import RECIPES

DEVICE = re.compile(r"^(cpu|cuda(:\d+)?)$")


@dataclass(frozen=True)
class ReproduceConfig:
    """Regenerate the README's measured tables with the README's own settings (data, training, benchmarks), each
    written beside the README's figures with the difference. A killed run continues where it stopped: run the same
    command again."""

    only: tuple[str, ...] = ()          # recipes to run, by name (levels reaching, or levels,reaching); empty: all
    out: Path = Path("results/reproduce")   # a run writes <out>/<run-id>/ (data, runs, results, tables.md)
    run_id: str | None = None           # continue this run; None: the newest unfinished run of the same recipes
    fresh: bool = False                 # start a new run even when an unfinished one exists
    device: str = "cpu"                 # cpu | cuda | cuda:N: where networks train and run
    workers: int = 2                    # datagen processes (one per core of the reference machine)
    estimate: bool = True               # probe every pending step at a small size first and print the cost
    dry_run: bool = False               # print the steps and the estimate; run nothing
    tracking_uri: str | None = None     # None: sqlite:///<run>/mlflow.db (the reproduction's own registry)
    readme: Path | None = None          # the README whose tables are compared; None: this checkout's
    progress: bool = False              # progress bars of every step (on from the CLI)

    def __post_init__(self):
        names = tuple(name for given in self.only for name in given.split(",") if name)   # "levels,reaching" too
        object.__setattr__(self, "only", names)
        unknown = [name for name in self.only if name not in RECIPES]
        if unknown:
            raise ValueError(must_be("--only", f"names among {sorted(RECIPES)}", list(self.only),
                                     f"{unknown} name no recipe."))
        if not DEVICE.match(self.device):
            raise ValueError(must_be("--device", "cpu, cuda or cuda:N", self.device))
        if self.workers < 1:
            raise ValueError(must_be("--workers", "at least 1", self.workers))
        if self.run_id is not None and self.fresh:
            raise ValueError(must_be("--run-id with --fresh", "one or the other", "both",
                                     "--run-id continues a run, --fresh starts a new one."))
