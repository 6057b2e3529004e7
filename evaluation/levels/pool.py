"""The runs of a levels benchmark in worker processes (`--workers N`), a batch of runs (run_batch.py) at a time.

A run's trials form one batch whose updates are small convolutions or kinematics: torch's intra-op threads gain
little on them and lose much on a loaded machine, so on several cores the runs go to processes of their own, the
torch threads split among them. Runs are independent (targets and beliefs seeded by the run's index) and the work of
a run is the same wherever it runs, so the rows do not depend on the number of workers beyond the rounding of the
batches they cut (run_batch.py: none with one run per batch, ~1e-10 rad for float64 models). Workers are spawned
(no fork of a process holding torch threads or a GL context) and build their robot once; models travel pickled, and
a worker checks its copies' predictions against the originals' before its first run (a model whose state does not
survive pickling would otherwise score wrong rows).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor

import torch

from bodyschema.errors import must_be

_WORKER: dict = {}                   # per worker process: the run function and its fixed arguments


def map_runs(measure: Callable, config, models: Sequence, encoder, batches: Sequence[tuple[int, ...]],
             workers: int) -> Iterator:
    """measure(config, models, encoder, runs) for each batch of runs over `workers` processes, in order."""
    threads = max(1, torch.get_num_threads() // workers)
    probe = _probe(models)
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_start,
                             initargs=(threads, measure, config, list(models), encoder, probe)) as pool:
        yield from pool.map(_run, batches)


def _probe(models: Sequence) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """Poses across each joint's range and every model's prediction there. → (5, Dz) rad, [(5, *out)]"""
    low, high = (torch.as_tensor(b, dtype=torch.float64) for b in (models[0].body.q_low, models[0].body.q_high))
    z = low + torch.linspace(0.1, 0.9, 5, dtype=torch.float64)[:, None] * (high - low)
    return z, [m.predict(z.to(getattr(m, "compute_dtype", z.dtype))) for m in models]


def _start(threads: int, measure: Callable, config, models: list, encoder, probe) -> None:
    torch.set_num_threads(threads)
    _WORKER.update(measure=measure, args=(config, models, encoder), probe=probe)


def _run(runs: tuple[int, ...]):
    probe = _WORKER.pop("probe", None)
    if probe is not None:                                                  # the first batch of this worker
        models = _WORKER["args"][1]
        for m, want, got in zip(models, probe[1], _probe(models)[1]):
            if not torch.allclose(got, want, rtol=1e-5, atol=1e-6):
                raise ValueError(must_be("models", "the same after pickling (a worker process gets a copy)",
                                         f"{getattr(m, 'kind', type(m).__name__)}:{m.modality} predicting "
                                         f"{float((got - want).abs().max()):.3g} off", "Run with --workers 1."))
    return _WORKER["measure"](*_WORKER["args"], runs)
