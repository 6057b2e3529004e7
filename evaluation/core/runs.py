"""Run folders: every benchmark run writes `<out>/<run-id>/` and then points `<out>/latest` at it, so a run never
overwrites another. The run id is the UTC start time and a short hash of the config: it sorts by time and says
which runs share a config (`20261124T201502.123Z-1a2b3c4d`).

A run folder starts with `run.json`: the config's class and fields, and the robot when the config names one. A run
on a robot also moves `<out>/latest-<robot>`, so `evaluate reaching --robot panda` after a nao_arm run leaves
`latest-nao_arm` where it was: `latest` is the newest run of any robot, `latest-<robot>` the newest on each
(`latest_runs`). A folder written before run.json existed has `latest` only, and reads as before.

A run is complete once its `latest` links move to it: `mark_latest` first sets `"complete": true` in its run.json
(written `false` by new_run), the run's last write. A run killed before has `false`: `report` skips it, saying so,
and the next run of the same benchmark folder removes it once the process that wrote it is gone (its pid, host and
process start time are in run.json: a run still going is never touched). A run.json without the key predates it and
counts as complete.
"""

from __future__ import annotations

import calendar
import contextlib
import functools
import hashlib
import json
import os
import re
import shutil
import socket
import time
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import asdict, is_dataclass
from pathlib import Path

from bodyschema.base.processes import start_time

LATEST = "latest"
RUN_FILE = "run.json"                 # what the run is: its config's class and fields, its robot
MAX_RUN_FILE_BYTES = 1_000_000        # a larger run.json was not written by new_run: not read
COMPLETE = "complete"                 # run.json's key: false until the run's last write (mark_latest)
MODELS_CSV = "models.csv"             # the models a run used (spec, name, version, source run, digest)
RUN_NAME = re.compile(r"^\d{8}T\d{6}\.\d{3}Z-[0-9a-f]{8}(-\d+)?$")
PLAIN_NAME = re.compile(r"^[\w.-]+$")  # a shipped robot's name, usable as is in a link name


_STARTED: ContextVar[float | None] = ContextVar("bodyschema_benchmark_started", default=None)
_RESOLVED: ContextVar[float | None] = ContextVar("bodyschema_models_resolved", default=None)   # see note_start


@contextlib.contextmanager
def benchmark_clock():
    """Time a benchmark run from here: its MLflow run starts at this moment (`benchmark_started`). The registry's
    runners (`evaluation.registry`, what `bodyschema evaluate` calls) run under it."""
    token = _STARTED.set(time.time())
    try:
        yield
    finally:
        _STARTED.reset(token)


@functools.cache
def clocked(runner: Callable) -> Callable:
    """`runner` under `benchmark_clock` (one wrapper per runner: `clocked(f) is clocked(f)`)."""
    @functools.wraps(runner)
    def run(*args, **kwargs):
        with benchmark_clock():
            return runner(*args, **kwargs)
    return run


def note_start() -> None:
    """A benchmark is starting: every runner resolves its models first (`specs.resolve_models` calls this). The first
    call since the last `benchmark_started` counts, so a later resolve inside the same run does not move it."""
    if _RESOLVED.get() is None:
        _RESOLVED.set(time.time())


def benchmark_started(folder: Path | None = None) -> float:
    """When the benchmark being published began, s since the epoch (and the `note_start` mark is cleared): the
    innermost `benchmark_clock`'s start; outside one (a runner called directly from Python, as the demo does), when it
    resolved its models (`note_start`); else the creation of its run folder (the UTC time in its name), else now."""
    resolved = _RESOLVED.get()
    _RESOLVED.set(None)
    started = _STARTED.get()
    if started is not None:
        return started
    if resolved is not None:
        return resolved
    match = RUN_NAME.match(Path(folder).name) if folder is not None else None
    if match is None:
        return time.time()
    stamp = Path(folder).name
    return calendar.timegm(time.strptime(stamp[:15], "%Y%m%dT%H%M%S")) + int(stamp[16:19]) / 1000


def config_hash(config) -> str:
    """8 hex digits of the sha256 of the config's fields (paths and tuples as text, keys sorted)."""
    text = json.dumps(_fields(config), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def _fields(config) -> dict:
    return asdict(config) if is_dataclass(config) else dict(config)


def run_id(config, now: float | None = None) -> str:
    now = time.time() if now is None else now
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime(now)) + f".{int(now * 1000) % 1000:03d}Z"
    return f"{stamp}-{config_hash(config)}"


def run_record(config) -> dict:
    """run.json's content: which benchmark config ran (class and module), on which robot (None: the config names
    none, the models decide), with which fields."""
    robot = getattr(config, "robot", None)
    return {"config": type(config).__name__, "module": type(config).__module__,
            "robot": str(robot) if robot is not None else None, "fields": _fields(config), COMPLETE: False,
            "writer": _writer()}


def _writer() -> dict:
    """Who writes the run: this process (pid, host, start time in clock ticks since boot: a pid reused after a
    reboot or by a later process does not match)."""
    return {"pid": os.getpid(), "host": socket.gethostname(), "started": start_time(os.getpid())}


def _writer_gone(writer) -> bool:
    """The process that wrote a run is known to be gone: on this host, and no process with its pid and start time.
    Unknown (another host, no /proc): not gone (the run is left alone)."""
    if not isinstance(writer, dict) or writer.get("host") != socket.gethostname():
        return False
    pid, started = writer.get("pid"), writer.get("started")
    if not isinstance(pid, int) or started is None or start_time(os.getpid()) is None:
        return False
    return start_time(pid) != started


def is_complete(folder: Path) -> bool:
    """The run finished (its run.json says so, or predates the marker); False for one killed, or still running."""
    return read_run_record(folder).get(COMPLETE, True) is not False


def mark_complete(folder: Path) -> None:
    """Set the run's completion marker (run.json's `complete`), atomically."""
    _rewrite_record(folder, {COMPLETE: True})


def remove_abandoned(root: Path) -> list[Path]:
    """Remove the incomplete runs under `root` whose writer is gone (killed runs); → the folders removed."""
    removed = []
    for folder in (p for p in Path(root).iterdir() if is_run_folder(p)):
        record = read_run_record(folder)
        if record.get(COMPLETE, True) is False and _writer_gone(record.get("writer")):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


def new_run(config) -> Path:
    """A fresh `<config.out>/<run-id>/` holding only its run.json (a suffix `-<k>` should two runs of one config
    start in the same millisecond): nothing another run wrote is touched."""
    root = Path(config.out)
    root.mkdir(parents=True, exist_ok=True)
    remove_abandoned(root)
    base = run_id(config)
    for k in range(1000):
        folder = root / (base if k == 0 else f"{base}-{k}")
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        (folder / RUN_FILE).write_text(json.dumps(run_record(config), indent=1, default=str) + "\n")
        return folder
    raise FileExistsError(f"{root}: 1000 runs named {base}-<k> already exist")


def record_robot(folder: Path, robot: str) -> None:
    """Name the robot in a run's run.json when its config named none (levels, robustness: the models' body decides),
    so its run gets its own `latest-<robot>` and a levels run on the panda leaves nao_arm's as it was."""
    if read_run_record(folder).get("robot") is None:
        _rewrite_record(folder, {"robot": str(robot)})


def _rewrite_record(folder: Path, changes: dict) -> None:
    """run.json with `changes`, replaced atomically (nothing for a run without one: a folder older than run.json)."""
    record = read_run_record(folder)
    if not record:
        return
    path = Path(folder) / RUN_FILE
    tmp = path.with_name(f".{RUN_FILE}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps({**record, **changes}, indent=1, default=str) + "\n")
    tmp.replace(path)


def read_run_record(folder: Path) -> dict:
    """A run folder's run.json as written by new_run; {} for a run written before it existed, or an unreadable one
    (the report still shows such a run, as one without a robot)."""
    path = Path(folder) / RUN_FILE
    try:
        if path.is_symlink() or path.stat().st_size > MAX_RUN_FILE_BYTES:
            return {}
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def robot_label(robot: str | None) -> str | None:
    """The name a robot's runs go by (`latest-<label>`, the report's section): a shipped robot's own name; for a
    robot from a file, the file's stem and 6 hex digits of its path, as two files may share a stem."""
    if robot is None:
        return None
    if PLAIN_NAME.match(robot) and robot not in (".", ".."):
        return robot
    stem = re.sub(r"[^\w.-]", "_", Path(robot).stem) or "robot"
    return f"{stem}-{hashlib.sha256(robot.encode()).hexdigest()[:6]}"


def run_robot(folder: Path) -> str | None:
    """The label of the robot a run names in its run.json; None: no robot (or a run older than run.json)."""
    robot = read_run_record(folder).get("robot")
    return robot_label(robot) if isinstance(robot, str) else None


def mark_latest(folder: Path) -> Path:
    """Point `<folder's parent>/latest`, and `latest-<robot>` for a run on a robot, at `folder` (relative links,
    each replaced atomically: a reader sees the old or the new run, never none); → the `latest` link. The run is
    marked complete first: this is its last write."""
    mark_complete(folder)
    robot = run_robot(folder)
    if robot is not None:
        _link(folder, f"{LATEST}-{robot}")
    return _link(folder, LATEST)


def _link(folder: Path, name: str) -> Path:
    link = folder.parent / name
    tmp = folder.parent / f".{name}.{os.getpid()}.tmp"
    tmp.unlink(missing_ok=True)
    os.symlink(folder.name, tmp)
    os.replace(tmp, link)
    return link


def is_run_folder(path: Path) -> bool:
    """A folder named like a run id (`<UTC time>-<config hash>`)."""
    return path.is_dir() and not path.is_symlink() and RUN_NAME.match(path.name) is not None


def is_benchmark_folder(path: Path) -> bool:
    """A benchmark's `out`: it holds a `latest` link or run folders."""
    return (path / LATEST).is_symlink() or any(is_run_folder(p) for p in path.iterdir())


def latest_run(root: Path) -> Path | None:
    """The run `<root>/latest` points at (as a path under root), else the newest complete run folder by name, else
    None."""
    return _target(Path(root) / LATEST) or max((p for p in Path(root).iterdir() if is_run_folder(p)
                                                and is_complete(p)), default=None)


def latest_runs(root: Path) -> dict[str | None, Path]:
    """The latest run on each robot under `root`: robot label (None: a run that names no robot) → run folder.
    `latest` counts for its own run's robot, each `latest-<robot>` for its robot."""
    runs = {}
    newest = latest_run(root)
    if newest is not None:
        runs[run_robot(newest)] = newest
    for link in sorted(Path(root).glob(f"{LATEST}-*")):
        target = _target(link)
        if target is not None:
            runs[link.name[len(LATEST) + 1:]] = target
    return runs


def _target(link: Path) -> Path | None:
    """The run folder a `latest` link names, as a path beside the link; None unless it is a link to a run folder
    there (a link elsewhere is no run of this benchmark)."""
    if not link.is_symlink():
        return None
    target = link.parent / os.readlink(link)
    return target if target.parent == link.parent and is_run_folder(target) else None
