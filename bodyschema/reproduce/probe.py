"""The cost estimate printed before a reproduction starts: every pending step run small in a scratch folder, timed,
and scaled to its full size. Datagen: PROBE_SAMPLES samples on one worker, scaled by the samples. Training: one
epoch on PROBE_ROWS rows, its fit alone scaled by rows × epochs (an upper bound: patience stops fits early); an exact
GP by the cube of the samples its marginal likelihood is fitted on.
A benchmark: PROBE_TRIALS trials of one run, its trials' time scaled by trials × runs, plus its fixed cost
(loading models, rendering, tables) once. CPU time is the process's and its children's; wall time is this machine's
now (a loaded machine gives a longer estimate).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import resource
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bodyschema import log
from bodyschema.reproduce import execute

PROBE_SAMPLES = 320          # datagen probe: 256 training rows after the default 20 % held out
PROBE_ROWS = 256             # training probe rows
PROBE_TRIALS = 8             # benchmark probe trials (one run)


@dataclass(frozen=True)
class StepCost:
    step: str
    cpu_seconds: float
    wall_seconds: float
    probe_seconds: float

    def __str__(self) -> str:
        return (f"  {self.step:<12} ~{self.cpu_seconds / 60:6.1f} CPU-min  ~{self.wall_seconds / 60:6.1f} min wall "
                f"(probe {self.probe_seconds:.1f} s)")


def estimate(steps, products: dict[str, str], values: dict[str, str], full_configs: dict) -> list[StepCost]:
    """The cost of each of `steps` (pending, in order); `products` of the finished ones, `values` the run's
    placeholders, `full_configs` each step's config at full size (for the scale)."""
    costs = []
    with tempfile.TemporaryDirectory(prefix="bodyschema-probe-") as scratch:
        probe_values = {**values, "run": scratch, "workers": "1", "tracking": f"sqlite:///{scratch}/mlflow.db"}
        probe_products = dict(products)
        for step in steps:
            small, scale = _shrunk(execute.parse(step.command.format(**probe_values, **probe_products)),
                                   full_configs[step.name], full_configs)
            cpu0, wall0 = _cpu(), time.perf_counter()
            with log.quiet_mlflow(), _silenced():      # the small runs' own lines (MLflow prints to stderr)
                done = execute.run(small, progress=False)
            cpu, wall = _cpu() - cpu0, time.perf_counter() - wall0
            probe_products[step.name] = done.product
            costs.append(_scaled(step.name, done, cpu, wall, scale, getattr(full_configs[step.name], "workers", 1)))
    return costs


def _scaled(name: str, done: execute.Done, cpu: float, wall: float, scale: float, workers: int) -> StepCost:
    work = done.fit_seconds if done.fit_seconds is not None else done.work_seconds
    if work is None:                                   # datagen: all of it scales, spread over its workers
        return StepCost(name, cpu * scale, wall * scale / workers, wall)
    fixed = max(wall - work, 0.0)
    busy = cpu / wall if wall > 0 else 1.0             # cores kept busy during the probe
    return StepCost(name, (fixed + work * scale) * busy, fixed + work * scale, wall)


def _shrunk(config, full, full_configs: dict):
    """(the small config, full size / small size)."""
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.training.config import TrainConfig

    if isinstance(config, DatagenConfig):
        return dataclasses.replace(config, n=PROBE_SAMPLES, workers=1, overwrite=True), full.n / PROBE_SAMPLES
    if isinstance(config, TrainConfig):
        epochs = getattr(full.model, "epochs", 1)
        model = dataclasses.replace(config.model, epochs=1) if hasattr(config.model, "epochs") else config.model
        rows = _training_rows(full, full_configs)
        small = dataclasses.replace(config, model=model, max_train=PROBE_ROWS)
        if hasattr(config.model, "epochs"):
            return small, rows / PROBE_ROWS * epochs
        # an exact GP: most of its fit is the marginal likelihood on min(rows, hyper_points) samples, O(m³) per step;
        # its one solve on max_points (or the kinematic kernel's 3^D features) takes seconds
        m = min(rows, getattr(config.model, "hyper_points", rows))
        return small, max(m / PROBE_ROWS, 1.0) ** 3
    trials, runs = getattr(full, "trials", PROBE_TRIALS), getattr(full, "runs", 1)
    changes = {k: v for k, v in (("trials", PROBE_TRIALS), ("runs", 1), ("plots", False)) if hasattr(config, k)}
    return dataclasses.replace(config, **changes), trials * runs / PROBE_TRIALS


def _training_rows(train, full_configs: dict) -> float:
    from bodyschema.datagen.config import DatagenConfig

    made = [c for c in full_configs.values() if isinstance(c, DatagenConfig) and Path(c.out) == Path(train.data)]
    n = made[0].n if made else PROBE_ROWS
    rows = n * (1 - train.val_fraction)
    return min(rows, train.max_train) if train.max_train else rows


@contextlib.contextmanager
def _silenced():
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        yield


def _cpu() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime
