"""The cost estimate `bodyschema sweep` prints before it starts: a short timed probe, scaled up.

The probe fits the sweep's first configuration on one thread (a trial gets one CPU) on a subset of the training rows:
one epoch for a network, the whole fit for a GP. Scaled to all rows, the epochs and the trials, it is an upper bound
for networks (patience and ASHA stop trials early); for a GP it is rough (its cost is not linear in the rows).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from bodyschema.threads import pinned
from bodyschema.training.config import untrained_model

PROBE_ROWS = 256          # rows the probe trains on: a second or so for the shipped kinds on one core


@dataclass(frozen=True)
class Cost:
    probe_seconds: float             # the timed probe (one epoch on PROBE_ROWS rows, or a GP fit on them)
    trial_seconds: float             # one trial, scaled to all rows and epochs
    trials: int
    concurrent: int

    @property
    def cpu_seconds(self) -> float:
        return self.trial_seconds * self.trials

    @property
    def wall_seconds(self) -> float:
        return self.cpu_seconds / self.concurrent

    def __str__(self) -> str:
        return (f"cost estimate: {self.trials} trials × ~{self.trial_seconds:.0f} s = ~{self.cpu_seconds / 60:.1f} CPU "
                f"min, ~{self.wall_seconds / 60:.1f} min on {self.concurrent} at once (probe "
                f"{self.probe_seconds:.2f} s; an upper bound for networks: early stopping cuts it)")


def estimate(p, data) -> Cost:
    """Time the probe of plan `p` on dataset `data` and scale it (see the module doc)."""
    first = p.space.first()
    config = dataclasses.replace(p.train, model=dataclasses.replace(p.train.model, **first))
    epochs = 1
    if p.network:
        epochs = getattr(config.model, "epochs", 1)
        config = dataclasses.replace(config, model=dataclasses.replace(config.model, epochs=1))
    n = min(PROBE_ROWS, len(data.train))
    rows = np.random.default_rng(config.seed).choice(len(data.train), n, replace=False)
    sub = data.train.take(np.sort(rows))
    model = untrained_model(config, data.body, {config.modality: data.output_shape(config.modality)})
    with pinned(1):
        started = time.perf_counter()
        model.fit(sub.q, sub.x, seed=config.seed, progress=False)
        probe = time.perf_counter() - started
    per_row = probe / n
    trial = per_row * (len(data.train) + len(data.val)) * epochs      # + the validation pass of every epoch
    return Cost(probe, trial, p.space.trials, p.concurrent)
