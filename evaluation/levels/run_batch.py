"""Several runs of a levels benchmark as one batch: their trials are inferred together and scored apart.

Perception steps every trial on its own (aif/perception.py), so a run's rows do not depend on which runs share its
batch, up to the rounding of a larger batch (float64 models: ~1e-10 rad, the order of blocked linear algebra; a
float32 network: a step taken or refused a float apart, ~1e-3 rad on a 56×80 decoder). What a batch saves is the
per-step work that does not grow with the trials (Python, small-kernel and host-synchronisation overhead) and the
tail: a run waits for its slowest trial, a batch for the slowest of all runs.

Measured side by side (nao_arm, level 2, 5 × 500 trials, one thread, 2-core CPU): analytic ee_xyz 3.4–3.9× faster,
a GP on ee_xyz 4.2×, the 56×80 lean decoder 0.8× (its convolutions slow down at 2 500 rows). Hence the rule in
`runs_per_batch`: every run of a worker in one batch for models without an image, or on a GPU; one run per batch
for an image model on the CPU.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from bodyschema.aif.perception import PerceptionResult
from bodyschema.base.modalities import is_image
from bodyschema.evaluation.levels.targets import Targets


@dataclass(frozen=True)
class RunBatch:
    targets: Targets                       # the runs' targets stacked, in run order: (Σ N_r, …)
    sizes: tuple[int, ...]                 # trials per run

    @classmethod
    def of(cls, parts: Sequence[Targets]) -> RunBatch:
        stacked = Targets(np.concatenate([p.q for p in parts]),
                          {m: np.concatenate([p.observations[m] for p in parts]) for m in parts[0].observations})
        return cls(stacked, tuple(len(p.q) for p in parts))

    def slices(self) -> list[slice]:
        ends = np.cumsum((0, *self.sizes))
        return [slice(int(a), int(b)) for a, b in zip(ends[:-1], ends[1:])]

    def part(self, i: int) -> Targets:
        """Run i's targets (i: its position in the batch)."""
        rows = self.slices()[i]
        return Targets(self.targets.q[rows], {m: x[rows] for m, x in self.targets.observations.items()})


def split_result(result: PerceptionResult, rows: slice) -> PerceptionResult:
    """The trials `rows` of a batched result; its evaluations are the batch's mean per trial times their number
    (a trial's own count is not kept), its trajectory their columns."""
    n = rows.stop - rows.start
    trajectory = None if result.trajectory is None else {k: v[:, rows] for k, v in result.trajectory.items()}
    return replace(result, mu=result.mu[rows], mu_tilde=result.mu_tilde[rows], steps=result.steps[rows],
                   converged=result.converged[rows], diverged=result.diverged[rows],
                   diverged_step=result.diverged_step[rows], F=result.F[rows],
                   evaluations=round(result.evaluations * n / len(result.mu)), trajectory=trajectory)


def reads_images(models: Sequence, encoder) -> bool:
    """Whether a levels run needs the targets' images: an image model, or an image encoder."""
    return encoder is not None or any(is_image(m.modality) for m in models)


def runs_per_batch(setting: int, models: Sequence, encoder, device: str) -> int:
    """How many runs share a batch: `setting` when given (≥ 1), else 0 meaning all of a worker's runs, except one
    for an image model on the CPU (measured slower in a larger batch: module docstring)."""
    if setting > 0:
        return setting
    return 1 if reads_images(models, encoder) and not device.startswith("cuda") else 0


def chunks(runs: int, workers: int, per_batch: int) -> list[tuple[int, ...]]:
    """range(runs) cut into consecutive batches: each worker's share, cut further to per_batch runs (0: no cap)."""
    share = -(-runs // max(1, workers))
    size = min(share, per_batch) if per_batch > 0 else share
    return [tuple(range(a, min(a + size, runs))) for a in range(0, runs, size)]
