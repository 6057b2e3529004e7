"""Where shards run: joblib's loky processes on this machine, or Ray (a local loopback-only instance, or RAY_ADDRESS).

Two safety rules hold for both:
- Workers die with their driver. A loky worker watches its parent pid and exits within `WATCH_S` once the driver
  is gone (after `kill -9` of `bodyschema datagen` they used to run on for ~6 min: loky's idle timeout).
- A local Ray binds to 127.0.0.1 only, without dashboard. Ray turns `_node_ip_address="127.0.0.1"` into the
  machine's routable address unless Ray clusters are disabled for this node (RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0,
  what Ray does by default on Windows/macOS); then GCS, raylet, object manager, runtime-env agent, workers and
  the driver listen on loopback (measured with Ray 2.60: `*:<port>` and the external IP before, 127.0.0.1 after).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from typing import Callable, Iterator

WATCH_S = 0.5  # s between checks of the parent pid: the worker exits at most this long after its driver
LOCAL_RAY_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}  # Ray's switch for a loopback-only node
IN_FLIGHT_PER_WORKER = 4  # Ray tasks submitted ahead per worker: the driver never holds every shard's task


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
def local_ray_env() -> Iterator[None]:
    """Environment for starting a loopback-only Ray in this process (restored afterwards)."""
    saved = {k: os.environ.get(k) for k in LOCAL_RAY_ENV}
    os.environ.update(LOCAL_RAY_ENV)  # read by Ray when imported, and by the processes it starts
    constants = sys.modules.get("ray._private.ray_constants")  # already imported: its flag was read at import
    flag = getattr(constants, "ENABLE_RAY_CLUSTER", None)
    if flag is not None:
        constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        if flag is not None:
            constants.ENABLE_RAY_CLUSTER = flag
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def run_ray(fn: Callable, jobs: list[tuple], workers: int, on_done: Callable[[int], None]) -> None:
    """Run fn(*job) for every job as Ray tasks: on the cluster named by RAY_ADDRESS, else on a local loopback Ray."""
    address = os.environ.get("RAY_ADDRESS")
    with contextlib.ExitStack() as stack:
        if not address:
            stack.enter_context(local_ray_env())
        import ray

        if not ray.is_initialized():
            if address:
                ray.init()  # the cluster named by RAY_ADDRESS (its nodes need bodyschema installed)
            else:
                ray.init(address="local", num_cpus=workers, include_dashboard=False, _node_ip_address="127.0.0.1",
                         log_to_driver=False, configure_logging=False)
            stack.callback(ray.shutdown)
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
