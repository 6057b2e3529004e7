"""Checks that run before a datagen job builds or writes anything: GL backend, writable folder, size, disk, memory,
rendering.

Everything here is O(1) in n: the shard count is computed, never listed, so `--n 1000000000000` is refused in
milliseconds instead of growing a Python list past the machine's memory (measured: > 23 GB before this check).
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from bodyschema.datagen.config import DatagenConfig
from bodyschema.errors import must_be

MAX_SHARDS = 100_000  # one done-marker file and one task per shard: beyond this the bookkeeping itself is the load
WORK_FACTOR = 3  # a worker holds ~3x its shard's stored bytes (float64 kinematics, the arrays, encode, read-back)




class RenderingUnavailable(OSError):
    """No OpenGL context could be made for rendering (MUJOCO_GL unusable on this machine)."""


def check_writable(path: Path) -> None:
    """Refuse an output whose nearest existing folder takes no new file (read-only, /proc, /sys); creates nothing."""
    folder = _existing_parent(path)
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".bodyschema-probe-"):
            pass
    except OSError as e:
        raise PermissionError(must_be(f"the folder of --out {path}", "writable", f"{folder}: {type(e).__name__}: {e}",
                                      "Choose --out in a folder you can write to; nothing was written.")) from e


def sample_bytes(feats: dict) -> int:
    """Stored (uncompressed) bytes of one sample of every array."""
    return sum(np.dtype(f["dtype"]).itemsize * math.prod(f["shape"]) for f in feats.values())


def n_shards(config: DatagenConfig, chunk_len: int) -> int:
    """How many shards `plan_shards` makes, without making them."""
    return -(-config.n // chunk_len)


def _existing_parent(path: Path) -> Path:
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


def available_memory() -> int | None:
    """Bytes of memory available to new work (Linux MemAvailable; free pages elsewhere); None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_resources(config: DatagenConfig, feats: dict, chunk_len: int, path: Path) -> None:
    """Refuse a job whose shard list, data or shards in flight exceed their limit, naming the limit and the fix."""
    shards, per_sample = n_shards(config, chunk_len), sample_bytes(feats)
    if shards > MAX_SHARDS:
        raise ValueError(must_be("n", f"<= {MAX_SHARDS * chunk_len} samples with {chunk_len}-row shards "
                                 f"(at most {MAX_SHARDS} shards)", config.n, "Raise --shard-size or lower --n."))
    need = config.n * per_sample  # raw bytes: the compressed store is smaller, never larger
    where = _existing_parent(path)
    free = shutil.disk_usage(where).free
    if free < need:
        raise OSError(must_be("free space at the output location", f">= {need / 1e6:.1f} MB (uncompressed data)",
                              f"{free / 1e6:.1f} MB free at {where}", "Free space, lower --n or choose another --out."))
    in_flight = WORK_FACTOR * chunk_len * per_sample * min(config.workers, shards)
    memory = available_memory()
    if memory is not None and in_flight > memory:
        raise ValueError(must_be("memory for the shards in flight", f"<= the {memory / 1e9:.2f} GB available",
                                 f"~{in_flight / 1e9:.2f} GB ({min(config.workers, shards)} workers x {chunk_len} rows "
                                 f"x {per_sample} B x {WORK_FACTOR})", "Lower --shard-size or --workers."))


def probe_render(robot) -> None:
    """Render one frame, so an unusable MUJOCO_GL fails here, before a store exists, not in every worker."""
    try:
        robot.render(robot.sampling_ranges.mean(axis=1)[None])  # (1, Dq) rad
    except Exception as e:  # noqa: BLE001 - mujoco.FatalError, GL import errors, ... all mean "no rendering"
        raise RenderingUnavailable(must_be(
            f"rendering (MUJOCO_GL={os.environ.get('MUJOCO_GL')!r})",
            "a working OpenGL backend: egl (headless GPU or Mesa), osmesa (software) or glfw (a display)",
            f"{type(e).__name__}: {e}",
            "Set MUJOCO_GL=egl or osmesa, or pass --no-images; nothing was written.")) from e
    finally:
        robot.close()
