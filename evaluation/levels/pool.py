"""The runs of a levels benchmark in worker processes (`--workers N`).

A run's trials form one batch whose updates are small convolutions or kinematics: torch's intra-op threads gain
little on them and lose much on a loaded machine, so on several cores the runs go to processes of their own, the
torch threads split among them. Runs are independent (targets and beliefs seeded by the run's index) and the work of
a run is the same wherever it runs, so the rows do not depend on the number of workers. Workers are spawned (no fork
of a process holding torch threads or a GL context) and build their robot once; models travel pickled.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor

import torch

_WORKER: dict = {}                   # per worker process: the run function and its fixed arguments


def map_runs(measure: Callable, config, models: Sequence, encoder, workers: int) -> Iterator:
    """measure(config, models, encoder, run) for run in range(config.runs) over `workers` processes, in run order."""
    threads = max(1, torch.get_num_threads() // workers)
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_start,
                             initargs=(threads, measure, config, list(models), encoder)) as pool:
        yield from pool.map(_run, range(config.runs))


def _start(threads: int, measure: Callable, config, models: list, encoder) -> None:
    torch.set_num_threads(threads)
    _WORKER.update(measure=measure, args=(config, models, encoder))


def _run(run: int):
    return _WORKER["measure"](*_WORKER["args"], run)
