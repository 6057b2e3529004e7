"""The floor of a levels run: perception started at the true pose, with the levels' own update and precisions, on the
run's held-out targets. It ends where F's own minimum lies near the truth, so no start of the levels can end lower
on average: what is left there is the model's (and its camera's) bias, not the inference's. The levels' rows carry
their gap to it (`gap_to_floor_deg`: judge an estimator by that gap), and a joint whose floor exceeds
`unobservable_deg` is flagged as not observable by this model/camera (measured on a 7-joint arm whose wrists the
decoder did not see: floors 44° and 52° where the other joints' were 0.8–4.9°, and the level-2 starts landed on them).

The floor is one more inference per run, for every model: an analytic model or a GP, milliseconds (one evaluation
per trial from the exact minimum); a pixel decoder, about one level row's cost, the image update (adam+lm) taking
its steps wherever it starts (a 16×16 test decoder, 50 trials, one thread: 1.19 s, 230 evaluations per trial, levels
1–3 1.15–1.38 s each), so about a quarter more perception on a levels run; `--no-floor` skips it.
A joint the model is strictly blind to (F exactly flat along it) is a limit of the measure: a first-order update
(adam, the image default's first half) does not move along it from the truth, so its floor reads ≈ 0 and the level
rows' gap shows it instead; a learned decoder is never exactly flat, and its spurious dependence is what moves the
floor (tests/evaluation/test_levels_floor.py).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import torch

from bodyschema.evaluation.core.tables import markdown_table
from bodyschema.evaluation.levels.run_batch import RunBatch
from bodyschema.evaluation.levels.scoring import observations, score_runs

FLOOR_LABEL = "floor"                  # the row's label in the level column
UNOBSERVABLE_DEG = 2.0                 # deg; a joint whose floor is above this is flagged (Pixel-AIF's ≤ 2° criterion)
GAP = "gap_to_floor_deg"               # a level row's mean joint error minus its run's floor, deg
JOINT = "joint_err_deg/"               # the per-joint columns' prefix


def evaluate_floor_runs(perception, robot, batch: RunBatch, success_deg: float = 1.0):
    """The floor of every run of a batch, inferred in one batch: per run (row, per-trial arrays, result)."""
    start = time.perf_counter()
    result = perception.infer(observations(perception, batch.targets), torch.from_numpy(batch.targets.q))
    return score_runs(perception.models, robot, batch, FLOOR_LABEL, result, result.evaluations,
                      time.perf_counter() - start, success_deg)


def add_gaps(rows: Sequence[dict], floor: Mapping) -> None:
    """Every row of one run gets its gap to that run's floor (deg), in place."""
    for row in rows:
        row[GAP] = row["joint_err_deg"] - floor["joint_err_deg"]


def unobservable(floor: Mapping, threshold_deg: float = UNOBSERVABLE_DEG) -> dict[str, float]:
    """joint name → its floor (deg), for the joints whose floor is above threshold_deg."""
    return {key.removeprefix(JOINT): value for key, value in floor.items()
            if key.startswith(JOINT) and not key.endswith("_std") and value > threshold_deg}


def floor_markdown(floor: Mapping, table: Sequence[Mapping], threshold_deg: float = UNOBSERVABLE_DEG) -> str:
    """summary.md's floor part: mean |joint error| per joint of the floor and of every level (with its gap to the
    floor), then one line per joint not observable by this model/camera."""
    joints = [key for key in floor if key.startswith(JOINT) and not key.endswith("_std")]
    text = (f"Floor: perception started at the true pose (same update, precisions and targets), mean |joint error| per "
            f"joint (deg); a level's gap to it is what its inference adds.\n\n"
            f"{markdown_table([floor, *table], (*joints, 'joint_err_deg', GAP), 'level')}\n")
    flagged = unobservable(floor, threshold_deg)
    if flagged:
        text += "\n" + "\n".join(f"- {name}: floor {deg:.2f}° > {threshold_deg:g}°: not observable by this "
                                 f"model/camera (perception started at the truth ends {deg:.2f}° off it)"
                                 for name, deg in flagged.items()) + "\n"
    return text
