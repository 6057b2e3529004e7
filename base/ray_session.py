"""Ray for the `with` body: the cluster named by RAY_ADDRESS, else a local loopback-only Ray that dies with its driver.

Used by datagen's Ray backend (datagen/backends.py) and `bodyschema sweep` (training/sweep.py).
- A local Ray dies with its driver. Its processes (GCS, raylet, dashboard, monitor, the raylet's agents and
  workers) outlived a `kill -9` of the driver by a minute or two, one agent listening on loopback; a watcher process
  (`reap_when_gone`) kills the driver's process tree within `WATCH_S` of its death.
- A local Ray binds to 127.0.0.1 only, without dashboard. Ray turns `_node_ip_address="127.0.0.1"` into the
  machine's routable address unless Ray clusters are disabled for this node (RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0,
  what Ray does by default on Windows/macOS); then GCS, raylet, object manager, runtime-env agent, workers and
  the driver listen on loopback (measured with Ray 2.60: `*:<port>` and the external IP before, 127.0.0.1 after).
- With RAY_ADDRESS, the address Ray will dial is first checked with a TCP connect of RAY_CONNECT_TIMEOUT_S (Ray
  itself retries an unreachable GCS for minutes and turns 127.0.0.1 into this machine's routable address).
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from typing import Iterator

from bodyschema.base.processes import WATCH_S, start_time, stat_field
from bodyschema.errors import must_be

LOCAL_RAY_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}  # Ray's switch for a loopback-only node
RAY_CONNECT_TIMEOUT_S = 5.0  # s to reach RAY_ADDRESS's GCS port: a cluster on a LAN answers in milliseconds


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


@contextlib.contextmanager
def ray_session(workers: int) -> Iterator:
    """Ray connected for the `with` body: the cluster named by RAY_ADDRESS, else a local loopback Ray (shut down)."""
    address = os.environ.get("RAY_ADDRESS")
    with contextlib.ExitStack() as stack:
        if not address:
            stack.enter_context(local_ray_env())
        ray = _import_ray()
        if not ray.is_initialized():
            if address:
                check_reachable(address)
                ray.init()  # the cluster named by RAY_ADDRESS (its nodes need bodyschema installed)
            else:
                stack.enter_context(_reaper())           # before ray.init: a kill during it is covered too
                ray.init(address="local", num_cpus=workers, include_dashboard=False, _node_ip_address="127.0.0.1",
                         log_to_driver=False, configure_logging=False)
            stack.callback(ray.shutdown)
        yield ray


@contextlib.contextmanager
def _reaper() -> Iterator[None]:
    """A watcher of this process for the `with` body: should it die (kill -9 included), the watcher kills what this
    process started (the local Ray's processes); a normal end stops the watcher (ray.shutdown ends Ray)."""
    watcher = subprocess.Popen([sys.executable, "-c", "import sys; from bodyschema.base.ray_session import "
                                "reap_when_gone; reap_when_gone(int(sys.argv[1]))", str(os.getpid())],
                               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)          # not in the driver's group: a Ctrl-C is not its
    try:
        yield
    finally:
        watcher.kill()
        watcher.wait()


def reap_when_gone(driver: int) -> None:
    """Run in the watcher process: every WATCH_S, note the process tree of `driver` (pid and start time of each
    descendant); once the driver is gone, SIGKILL that tree (its processes still alive, and their children), then
    exit. Linux /proc only (elsewhere: returns at once, Ray's own timeouts end its processes)."""
    started = start_time(driver)
    if started is None:
        return
    tree: dict[int, int] = {}
    while start_time(driver) == started:
        tree = _descendants({driver: started})
        time.sleep(WATCH_S)
    for _ in range(3):                               # a process forked while the tree was being killed: again
        alive = {pid: t for pid, t in tree.items() if start_time(pid) == t}
        tree = {**alive, **_descendants(alive, include_roots=False)}
        tree.pop(os.getpid(), None)
        if not tree:
            return
        for pid in tree:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.1)


def _descendants(roots: dict[int, int], include_roots: bool = False) -> dict[int, int]:
    """pid → start time of every process below `roots` (pid → start time) in the process tree, read from /proc."""
    children: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            parent = stat_field(int(entry.name), 3)
            if parent is not None:
                children.setdefault(parent, []).append(int(entry.name))
    found, todo = {}, list(roots)
    while todo:
        pid = todo.pop()
        for child in children.get(pid, ()):
            started = start_time(child)
            if started is not None and child not in found and child != os.getpid():
                found[child] = started
                todo.append(child)
    if include_roots:
        found.update(roots)
    return found


def _import_ray():
    try:
        import ray
    except ImportError as e:
        raise ValueError(must_be("--backend ray", "backed by an installed Ray", f"{type(e).__name__}: {e}",
                                 "pip install 'bodyschema[ray]', or use --backend loky (local cores).")) from e
    return ray


def ray_dial_address(address: str) -> str | None:
    """host:port that Ray will connect to for `address` (Ray Client's ray:// as given); None: nothing to dial."""
    if address.startswith("ray://"):
        return address.removeprefix("ray://")
    from ray._private.services import canonicalize_bootstrap_address

    try:
        return canonicalize_bootstrap_address(address)  # "auto": the running cluster; 127.0.0.1 -> this node's IP
    except ValueError as e:
        raise ValueError(must_be("RAY_ADDRESS", "host:port, ray://host:port or auto", address, str(e))) from e


def check_reachable(address: str, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """Raise ConnectionError (the house message) unless the port Ray dials for `address` accepts a TCP connection."""
    dial = ray_dial_address(address)
    if dial is None:
        return  # "local", or "auto" without a running cluster: ray.init says so at once
    host, _, port = dial.rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except (OSError, ValueError) as e:
        raise ConnectionError(must_be(
            "RAY_ADDRESS", f"a Ray cluster accepting connections within {timeout_s:g} s",
            f"{address} (Ray dials {dial}): {type(e).__name__}: {e}",
            "Start the cluster (`ray start --head`) or unset RAY_ADDRESS for a local Ray; Ray replaces "
            "127.0.0.1/localhost by this machine's address. Nothing was written.")) from e
