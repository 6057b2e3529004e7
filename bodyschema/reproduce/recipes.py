"""The README's measured tables as recipes: the commands that made each one, and how its rows and columns map onto the
results those commands write. `bodyschema reproduce` runs them (run.py) and compares (readme_tables.py).

A step is a command line after `bodyschema`, as a user would type it, with placeholders: `{run}` (the reproduce run's
folder), `{workers}`, `{device}`, `{tracking}` (its MLflow store) and `{<step>}` (an earlier step's product: a
dataset's path, a model's `models:/<name>/<version>`, a benchmark's run folder). Steps are named once and shared:
a recipe that needs the levels' decoder names the step `decoder`, which runs once for every recipe that needs it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Step:
    name: str
    command: str                     # after `bodyschema`; the README's own settings


@dataclass(frozen=True)
class Column:
    readme: str                      # the README table's header cell
    result: str                      # the column of the results CSV
    scale: float = 1.0               # result × scale is in the README's unit (a fraction shown as % → 100)


@dataclass(frozen=True)
class Table:
    marker: str                      # the README holds `<!-- reproduce: <marker> -->` right above the table
    step: str                        # the step whose folder holds `csv`
    csv: str
    key: str                         # the CSV column naming a row
    rows: tuple[tuple[str, str], ...]          # (the README row's first cell starts with, the CSV key)
    columns: tuple[Column, ...]
    spread: str | None = None        # the README column whose "± s" is the stated tolerance


@dataclass(frozen=True)
class Recipe:
    name: str
    about: str
    steps: tuple[Step, ...]
    table: Table


NAO_DATA = Step("nao_data", "datagen --robot nao_arm --n 18000 --workers {workers} --seed 0 "
                            "--out {run}/data/nao_arm.zarr")
DECODER = Step("decoder", "train pixel --data {nao_data} --epochs 60 --seed 0 --run-root {run}/runs "
                          "--tracking-uri {tracking} --device {device}")
ENCODER = Step("encoder", "train encoder --data {nao_data} --epochs 40 --seed 0 --run-root {run}/runs "
                          "--tracking-uri {tracking} --device {device}")

LEVELS = Recipe(
    name="levels",
    about="the levels benchmark, 5 runs × 500 trials, lean pixel decoder + encoder (README: Estimation levels)",
    steps=(NAO_DATA, DECODER, ENCODER,
           Step("levels", "evaluate levels --model {decoder} --encoder {encoder} --multistart 0 --runs 5 "
                          "--trials 500 --seed 0 --out {run}/results/levels --tracking-uri {tracking} "
                          "--device {device}")),
    table=Table(marker="levels", step="levels", csv="summary.csv", key="level",
                rows=(("1 (", "1"), ("1 +", "1+enc"), ("2 (", "2"), ("2 +", "2+enc"), ("3 (", "3"),
                      ("3 from", "3+enc")),
                columns=(Column("mean", "joint_err_deg"), Column("median", "joint_err_median_deg"),
                         Column("every joint ≤ 2°", "all_joints_2deg", 100.0),
                         Column("LElbowYaw", "joint_err_deg/LElbowYaw"),
                         Column("evaluations per trial", "evaluations_per_trial")),
                spread="mean"),
)

RECIPES: dict[str, Recipe] = {r.name: r for r in (LEVELS,)}
