"""Run folders: every benchmark run writes `<out>/<run-id>/` and then points `<out>/latest` at it, so a run never
overwrites another. The run id is the UTC start time and a short hash of the config: it sorts by time and says
which runs share a config (`20261124T201502.123Z-1a2b3c4d`)."""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
from dataclasses import asdict, is_dataclass
from pathlib import Path

LATEST = "latest"
MODELS_CSV = "models.csv"             # the models a run used (spec, name, version, source run, digest)
RUN_NAME = re.compile(r"^\d{8}T\d{6}\.\d{3}Z-[0-9a-f]{8}(-\d+)?$")


def config_hash(config) -> str:
    """8 hex digits of the sha256 of the config's fields (paths and tuples as text, keys sorted)."""
    fields = asdict(config) if is_dataclass(config) else dict(config)
    text = json.dumps(fields, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def run_id(config, now: float | None = None) -> str:
    now = time.time() if now is None else now
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime(now)) + f".{int(now * 1000) % 1000:03d}Z"
    return f"{stamp}-{config_hash(config)}"


def new_run(config) -> Path:
    """A fresh, empty `<config.out>/<run-id>/` (a suffix `-<k>` should two runs of one config start in the same
    millisecond): nothing another run wrote is touched."""
    root = Path(config.out)
    root.mkdir(parents=True, exist_ok=True)
    base = run_id(config)
    for k in range(1000):
        folder = root / (base if k == 0 else f"{base}-{k}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue
    raise FileExistsError(f"{root}: 1000 runs named {base}-<k> already exist")


def mark_latest(folder: Path) -> Path:
    """Point `<folder's parent>/latest` at `folder` (a relative link, replaced atomically: a reader sees the old or
    the new run, never none)."""
    link = folder.parent / LATEST
    tmp = folder.parent / f".{LATEST}.{os.getpid()}.tmp"
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
    """The run `<root>/latest` points at (as a path under root), else the newest run folder by name, else None."""
    link = Path(root) / LATEST
    if link.is_symlink() and (root / os.readlink(link)).is_dir():
        return Path(root) / os.readlink(link)
    runs = sorted(p for p in Path(root).iterdir() if is_run_folder(p))
    return runs[-1] if runs else None
