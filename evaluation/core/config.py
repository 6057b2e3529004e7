"""`BenchmarkConfig`: the fields every benchmark shares, declared once; a benchmark's config derives from it and
sets its own `out` and `experiment` defaults.

Its check covers every number of the config, nested configs (perception, action, AIC, PD) included, in one place:
every number is finite and ≥ 0 (no benchmark has a meaningful negative, NaN or infinite setting), and a count or
duration named in `LIMITS` lies within its bounds. A flag means the same in every benchmark (`--trials` counts
independent trials everywhere), so its bounds are keyed by name, not repeated per config; a config bounds the
counts it derives (frames = duration / period) with `within`.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from pathlib import Path

from bodyschema.cli_marks import Ungrouped
from bodyschema.errors import must_be
from bodyschema.log import Progress


@dataclass(frozen=True)
class Limit:
    """The accepted range of a count or duration, and why the upper bound is where it is."""

    least: float                       # smallest accepted value (exclusive when `open_low`)
    most: float                        # largest accepted value
    why: str                           # the hint of the error above `most`
    unit: str = ""
    open_low: bool = False             # `least` itself is refused (a duration of 0 s is no episode)


ONE_BATCH = "Every trial of a run is held in memory at once, as one batch"
# Far above what any setting means (defaults: 10–500 trials, 1–5 runs, 3–30 s, 20–120 frames, ≤ 300 updates), far
# below a run that would not end or not fit: each bound says why it is there (the error's hint).
LIMITS = {
    "trials": Limit(1, 10_000, f"{ONE_BATCH} (defaults 10–500); for more, run again with another --seed."),
    "runs": Limit(1, 100, "Runs repeat the whole batch one after another (default 5); for more, run again with "
                  "another --seed."),
    "steps": Limit(1, 10_000, "Every frame of every trial is simulated and kept (defaults 20–120 frames)."),
    "duration": Limit(0, 600.0, "Every control tick of every trial is simulated and kept (defaults 3–30 s per "
                      "episode).", unit="s", open_low=True),
    "max_steps": Limit(1, 100_000, "A perception that has not converged in thousands of updates will not "
                       "(default 300)."),
    "screen_steps": Limit(1, 100_000, "Updates of every start before pruning (default 5)."),
    "plain_steps": Limit(0, 100_000, "Euler steps of the plain Pixel-AIF reference per trial (default 5000)."),
    "multistart": Limit(0, 64, f"Starts multiply the batch; {ONE_BATCH.lower()} (default 8)."),
    "check_every": Limit(1, 1000, "Adam's or LM's steps between two reads of which trials stopped (default 1); a "
                         "trial runs on frozen up to that many steps."),
    "keep": Limit(1, 64, "Starts per trial refined to convergence, at most --multistart (default 2)."),
    "goal_starts": Limit(1, 64, f"Starts multiply the batch; {ONE_BATCH.lower()} (default 8)."),
    "perception_steps": Limit(1, 1_000, "Perception updates run on every control tick (defaults 1–2)."),
    "path_plots": Limit(0, 100, "Paths drawn in one plot (default 6)."),
    "strokes": Limit(0, 1_000, "Every felt stroke of an episode is compared with every seen one (default 30)."),
    "budget": Limit(1, 1_000, "Model evaluations per stream and frame: a frame's whole work (default 4)."),
    "calibration_frames": Limit(2, 100_000, "Poses whose free energy at the truth sets the lost-track threshold "
                                "(default 200)."),
    "recovery_frames": Limit(1, 10_000, "Frames a lost track may take to count as recovered (default 3)."),
    "restart_starts": Limit(1, 64, f"Starts multiply the batch; {ONE_BATCH.lower()} (default 8)."),
    "workers": Limit(1, 64, "Each worker process holds the models and one run's batch (default 1; 2–3 on 2 cores)."),
    "run_batch": Limit(0, 100, "Runs inferred in one batch, at most --runs (default 0: all of a worker's, one for "
                       "image models on the CPU)."),
}
# Integers that are no counts of work, each bounded by a check of its own: a value from a list (order, levels, level),
# the robot's image size limits (image_size), max_steps (patience: steps without progress), ≥ 0 (seed).
BOUNDED_ELSEWHERE = ("seed", "order", "levels", "level", "image_size", "patience")


@dataclass(frozen=True)
class BenchmarkConfig:
    """Shared by every benchmark: seeding, where runs go, MLflow, progress bars."""

    seed: int = 0                      # seeds every random draw of the run (targets, starts, noise)
    out: Path = Path("results")        # the benchmark's folder: a run writes <out>/<run-id>/ and links <out>/latest
    mlflow: bool = True                # log the run (config, metrics, files, the models it used) to MLflow
    tracking_uri: str | None = None    # None: $MLFLOW_TRACKING_URI, else sqlite:///mlflow.db
    experiment: str = "bodyschema"     # the MLflow experiment of the run
    progress: Progress = False         # show progress bars (--quiet hides them too)

    def __post_init__(self):
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(must_be("seed", "an integer ≥ 0", self.seed))
        check_numbers(self)


@dataclass(frozen=True)
class TrialsConfig(BenchmarkConfig):
    """A benchmark of independent trials: `--trials` counts them (targets, episodes, goal poses alike)."""

    trials: int = 100                  # independent trials (episodes) of the run


def check_numbers(config, prefix: str = "") -> None:
    """The house error for the first number of `config` (nested configs and tuples included) that is NaN,
    infinite or negative, or a field named in LIMITS outside its bounds."""
    for field in dataclasses.fields(config):
        name, value = prefix + field.name, getattr(config, field.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            check_numbers(value, prefix=prefix if _unprefixed(config, field.name) else f"{name}.")
            continue
        if field.name in LIMITS and value is not None:
            within(name, value, field.name)
        if any(_bad(x) for x in _numbers(value)):
            expected = "finite numbers ≥ 0" if isinstance(value, tuple) else "a finite number ≥ 0"
            raise ValueError(must_be(name, expected, value))


def _unprefixed(config, name: str) -> bool:
    """Whether the CLI spells the nested group `name` of config without a prefix of its own (marked `Ungrouped`,
    e.g. PerceptionConfig's per-algorithm settings: `--perception.dt`), so the error names the flag as it is typed."""
    hint = typing.get_type_hints(type(config), include_extras=True)[name]
    return any(isinstance(meta, Ungrouped) for meta in getattr(hint, "__metadata__", ()))


def within(name: str, value: float, limit: str) -> None:
    """The house error unless `value` (of the field or derived quantity `name`) lies within LIMITS[limit]."""
    bound = LIMITS[limit]
    unit = f" {bound.unit}" if bound.unit else ""
    if value < bound.least or (bound.open_low and value == bound.least):
        raise ValueError(must_be(name, f"{'greater than' if bound.open_low else 'at least'} {bound.least:g}{unit}",
                                 value))
    if value > bound.most:
        raise ValueError(must_be(name, f"at most {bound.most:g}{unit}", value, bound.why))


def _bad(x: float) -> bool:
    return x < 0 or (isinstance(x, float) and not math.isfinite(x))    # an int is finite (and may not fit a float)


def _numbers(value) -> list[float]:
    """The numbers in a field's value (bools are not numbers here; strings, paths and None hold none)."""
    if isinstance(value, (tuple, list)):
        return [x for item in value for x in _numbers(item)]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [value]
    return []


def check_names(name: str, values: tuple[str, ...], allowed: tuple[str, ...]) -> None:
    """The house error unless `values` is a non-empty tuple of distinct names among `allowed`."""
    if not values or len(set(values)) != len(values) or set(values) - set(allowed):
        raise ValueError(must_be(name, f"distinct names among {allowed}", values))
