"""Where shards run: joblib's loky processes on this machine, or Ray (a local loopback-only instance, or RAY_ADDRESS).

Two safety rules hold for both:
- Workers die with their driver. A loky worker watches its parent pid and exits within `WATCH_S` once the driver
  is gone (after `kill -9` of `bodyschema datagen` they used to run on for ~6 min: loky's idle timeout).
- A local Ray dies with its driver, and listens on loopback only (base/ray_session.py).

`backend(name, workers)` brings the backend up before the caller creates anything, and yields the runner.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from typing import Callable, Iterator

from bodyschema.base.processes import WATCH_S
from bodyschema.base.ray_session import ray_session

IN_FLIGHT_PER_WORKER = 4  # Ray tasks submitted ahead per worker: the driver never holds every shard's task
Runner = Callable[[Callable, list, Callable[[int], None]], None]  # runner(fn, jobs, on_done)


def exit_with_parent(parent: int) -> None:
    """Worker initializer: exit this process within WATCH_S of its parent `parent` (the driver) going away."""
    if os.getppid() != parent:
        os._exit(1)  # the driver died before this worker got going

    def watch() -> None:
        while os.getppid() == parent:  # a dead parent re-parents us (to init or a subreaper)
            time.sleep(WATCH_S)
        os._exit(1)  # no cleanup: the driver that would collect our result is gone; its shard is rerun on resume

    threading.Thread(target=watch, name="bodyschema-exit-with-driver", daemon=True).start()


def run_loky(fn: Callable, jobs: list[tuple], workers: int, on_done: Callable[[int], None]) -> None:
    """Run fn(*job) for every job on `workers` local processes; on_done(1) after each."""
    from joblib import Parallel, delayed

    parallel = Parallel(n_jobs=workers, backend="loky", return_as="generator_unordered",
                        initializer=exit_with_parent, initargs=(os.getpid(),))
    for _ in parallel(delayed(fn)(*job) for job in jobs):
        on_done(1)


@contextlib.contextmanager
def backend(name: str, workers: int) -> Iterator[Runner]:
    """The backend `name` ("loky" | "ray") up and running for the `with` body: yields runner(fn, jobs, on_done)."""
    if name != "ray":
        yield lambda fn, jobs, on_done: run_loky(fn, jobs, workers, on_done)
        return
    with ray_session(workers) as ray:
        yield lambda fn, jobs, on_done: run_ray(ray, fn, jobs, workers, on_done)


def run_ray(ray, fn: Callable, jobs: list[tuple], workers: int, on_done: Callable[[int], None]) -> None:
    """Run fn(*job) for every job as Ray tasks on the connected Ray, at most IN_FLIGHT_PER_WORKER per worker ahead."""
    task = ray.remote(num_cpus=1, max_retries=0)(fn)
    todo, pending = iter(jobs), []
    window = IN_FLIGHT_PER_WORKER * workers
    while True:
        pending += [task.remote(*job) for job in _take(todo, window - len(pending))]
        if not pending:
            break
        done, pending = ray.wait(pending, num_returns=1)
        ray.get(done)
        on_done(len(done))


def _take(items: Iterator, k: int) -> list:
    return [item for _, item in zip(range(max(0, k)), items)]
