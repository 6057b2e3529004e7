"""`SweepConfig`: the flags of `bodyschema sweep KIND` (light: the CLI builds its help without importing Ray or torch).

The search space is given as text and read with the kind's own hyper-parameter types (sweep_space.py):
`--grid lr=1e-3,3e-3 channels=16x8,32x16` (every combination), `--random 8 --space lr=1e-4:1e-2:log` (8 draws per
grid point). The other fields are `bodyschema train`'s, with the same meaning.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from bodyschema.cli_marks import Positional
from bodyschema.errors import must_be

LIST_FLAGS = ("--grid", "--space")   # each takes its items after one flag: a second one would replace the first

KindWord = Annotated[str, Positional("KIND")]


@dataclass(frozen=True)
class SweepConfig:
    """Search a model kind's hyper-parameters on Ray Tune; register the best trial, champion only if better."""

    kind: KindWord  # the model kind, as in `bodyschema train KIND` (gpr, sklearn-gpr, mdn, pixel)
    data: Path  # the Zarr store written by `bodyschema datagen`
    modality: str | None = None  # what g predicts; None: the kind's default (image for pixel, else ee_xyz)
    grid: tuple[str, ...] = ()  # name=v1,v2 per hyper-parameter: every combination is a trial (lists as 64x64)
    random: int = 0  # draws from --space per grid point (Tune's num_samples); 0: a pure grid
    space: tuple[str, ...] = ()  # name=lo:hi or name=lo:hi:log: an int or float drawn uniformly (in log space)
    max_concurrent: int | None = None  # trials at once, 1 CPU each; None: as many as CPUs (and trials)
    epochs_budget: int | None = None  # epochs of every trial (a network kind's --epochs); None: the kind's default
    grace_period: int = 2  # epochs every network trial runs before ASHA may stop it
    seed: int = 0  # split, model init and the random draws; the same command draws the same trials
    val_fraction: float = 0.2  # held-out share (whole episodes when the store has `episode`)
    max_train: int | None = None  # cap on training samples; None: all of them
    experiment: str = "bodyschema"  # MLflow experiment of the parent run and its children
    tracking_uri: str | None = None  # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db
    run_root: Path = Path("runs")  # the sweep folder is <run_root>/sweeps/<kind>-<modality>-<hash>
    register: bool = True  # register the best trial (champion only if better); False: runs only
    progress: bool = True  # Tune's trial table on the console


def check_sweep_flags(argv: list[str]) -> None:
    """`sweep --grid a=1 --grid b=2` would sweep b only (the parser keeps a list flag's last occurrence): the house
    error, naming the one-flag form."""
    if argv[:1] != ["sweep"]:
        return
    for flag in LIST_FLAGS:
        given = [a for a in argv if a.split("=")[0] == flag]
        if len(given) > 1:
            raise ValueError(must_be(flag, "given once, all its items after it", f"{flag} {len(given)} times",
                                     f"Write `{flag} lr=1e-3,3e-3 hidden=64x64,128x128`: items separated by spaces, "
                                     "values by commas."))
