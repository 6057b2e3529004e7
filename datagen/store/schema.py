"""The Zarr v3 dataset store: schema (`features`), creation, chunk-aligned shard writes and the markers.

Layout of one store (a directory `*.zarr`), all data arrays sharing the first (sample) axis N:
    q (N, Dq) f32 rad · ee_xyz (N, 3) f32 m · ee_rot (N, 9) f32, the ee's rotation matrix row by row (stores made
    before it was recorded lack it) · ee_pixel (N, 2) f32 px · jacobian (N, 3, Dq) f32 m/rad
    image (N, H, W[, 3]) u8 (when rendered) · touch (N, 1) f32 N (robots with a touch sensor)
    babbling only: qvel (N, Dq) f32 rad/s (|qvel| <= MAX_JOINT_SPEED) · episode (N,) i32 · t (N,) f32 s since the
    episode start · target (N, Dq) f32 rad, the servo targets in force from each sample on, joint order as q (stores
    made before it was recorded lack it; they stay valid)
    shard_done (n_shards,) u64 — bookkeeping, one chunk per shard: 0 until the shard's data are written, then
    the shard's checksum (`integrity.shard_digest` of its rows of every array, read back as stored), so a chunk
    deleted, truncated or changed later is found by `validate_store` and rewritten by the next `datagen` run.
The sample-axis chunk length equals the shard length, so each worker writes whole chunks of its own: no locks.
Root attrs hold the metadata (robot, camera, sampler, seed, config, versions); `complete=True` is written last.
Float arrays are filled with NaN, so a sample never written shows up as NaN in `validate_store`; every chunk is
written even when it equals the fill value (`write_empty_chunks`), so a chunk file missing is always a defect.
"""

from __future__ import annotations

import datetime as dt
import importlib.metadata
import json
import platform
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from zarr.codecs import ZstdCodec

from bodyschema.base import modalities
from bodyschema.errors import must_be

SCHEMA_VERSION = 2  # 2: shard_done holds a per-shard checksum (1: a bare 0/1 flag); attrs reach_m, base_m
DONE = "shard_done"
COMPRESSORS = [ZstdCodec(level=1, checksum=True)]  # checksum: a flipped byte in a chunk is an error, not noise
# Attrs every complete store carries (validate_store checks them).
REQUIRED_ATTRS = ("schema_version", "robot", "mjcf_sha256", "dq", "joint_names", "joint_limits", "sampling_ranges",
                  "camera_name", "intrinsics", "extrinsics", "image_size", "channels", "images", "sampler",
                  "sampler_params", "seed", "config", "versions", "created_at", "n", "chunk_len", "n_shards",
                  "features", "complete", "reach_m", "base_m")
WRITE_ALL_CHUNKS = {"array.write_empty_chunks": True}  # zarr skips fill-valued chunks by default: never missing
MAX_JOINT_SPEED = 1e3  # rad/s; babbling measured <= 27 rad/s (panda, 9.81-100 m/s^2); a diverged simulation ~1e26


class StoreWriteError(OSError):
    """Writing the store failed (disk full, permissions, read-only, I/O); the message says what to do."""

    @classmethod
    def from_os_error(cls, path: Path | str, e: OSError) -> StoreWriteError:
        return cls(must_be("output location", f"writable, with free space, for {path}", f"{type(e).__name__}: {e}",
                           "Free space or choose another --out; rerunning the same command resumes "
                           "(finished shards are kept, the store is not marked complete)."))


def features(dq: int, image_shape: tuple[int, ...] | None, sensors: Iterable[str],
             babble: bool) -> dict[str, dict[str, Any]]:
    """The data arrays of a store as {name: {dtype, shape (per sample), unit, names}} (as LeRobot's features):
    the modality table's rows it holds (images when `image_shape` is given, the robot's `sensors`), then
    babbling's own arrays."""
    rows = modalities.stored(image_shape is not None, sensors)
    f: dict[str, dict[str, Any]] = {m.store_array: modalities.store_feature(m.name, dq, image_shape) for m in rows}
    if babble:
        f["qvel"] = {"dtype": "float32", "shape": [dq], "unit": "rad/s", "names": ["joint"]}
        f["episode"] = {"dtype": "int32", "shape": [], "unit": "index", "names": []}
        f["t"] = {"dtype": "float32", "shape": [], "unit": "s", "names": []}
        f["target"] = {"dtype": "float32", "shape": [dq], "unit": "rad", "names": ["joint"]}   # the babbling commands
    return f


def fill_value(dtype: str) -> float | int:
    """NaN for floats (unwritten samples are visible), -1 for indices, 0 for pixels."""
    return {"float32": float("nan"), "int32": -1, "uint8": 0}[dtype]


def versions() -> dict[str, str]:
    """Library versions recorded in every store."""
    out = {"python": platform.python_version()}
    for lib in ("numpy", "mujoco", "zarr", "bodyschema"):
        try:
            out[lib] = importlib.metadata.version(lib)
        except importlib.metadata.PackageNotFoundError:
            out[lib] = "unknown"
    return out


def now() -> str:
    """UTC time stamp (ISO 8601)."""
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def create_store(path: Path, feats: dict[str, dict[str, Any]], n: int, chunk_len: int, n_shards: int,
                 attrs: dict[str, Any]) -> zarr.Group:
    """Create (or recreate) an empty store: attrs first with complete=False, then arrays, then `created=True`.

    A kill in the middle leaves `created` unset, and the next run recreates the store from scratch.
    """
    root = zarr.open_group(str(path), mode="w", zarr_format=3,
                           attributes={**attrs, "complete": False, "created": False})
    for name, spec in feats.items():
        shape = (n, *spec["shape"])
        root.create_array(name, shape=shape, chunks=(chunk_len, *spec["shape"]), dtype=spec["dtype"],
                          fill_value=fill_value(spec["dtype"]), compressors=COMPRESSORS,
                          attributes={"unit": spec["unit"], "names": spec["names"]})
    root.create_array(DONE, shape=(n_shards,), chunks=(1,), dtype="uint64", fill_value=0, compressors=None)
    root.attrs["created"] = True
    return root


def open_store(path: Path, mode: str = "r") -> zarr.Group:
    """Open an existing store; a clear error when `path` is not a Zarr v3 group."""
    check_root_metadata(Path(path))
    try:
        return zarr.open_group(str(path), mode=mode, zarr_format=3)
    except (FileNotFoundError, zarr.errors.GroupNotFoundError, ValueError, KeyError) as e:
        raise FileNotFoundError(must_be("path", "a Zarr v3 dataset store (a directory with zarr.json)", str(path),
                                        "Create one with `bodyschema datagen --out PATH`.")) from e


def check_root_metadata(path: Path) -> None:
    """Raise the house ValueError when `path`/zarr.json exists but is not a JSON object (zarr fails obscurely)."""
    meta = path / "zarr.json"
    if not meta.is_file():
        return  # no store at all: open_store's own error says so
    try:
        value = json.loads(meta.read_bytes())
    except ValueError as e:  # not JSON, or not UTF-8
        raise ValueError(must_be(f"{meta}", "a JSON object (Zarr v3 group metadata)", f"unreadable JSON: {e}",
                                 "The store's root metadata was edited or truncated; regenerate the store.")) from e
    if not isinstance(value, dict):
        raise ValueError(must_be(f"{meta}", "a JSON object (Zarr v3 group metadata)", f"a JSON {type(value).__name__}",
                                 "The store's root metadata was edited or truncated; regenerate the store."))


def write_shard(root: zarr.Group, start: int, arrays: dict[str, np.ndarray]) -> None:
    """Write one shard's arrays at rows [start, start + len) — whole chunks, owned by this shard only."""
    with zarr.config.set(WRITE_ALL_CHUNKS):
        for name, values in arrays.items():
            root[name][start:start + len(values)] = values


def mark_shard_done(root: zarr.Group, shard: int, digest: int) -> None:
    """Record that shard `shard` is fully written, with its checksum (nonzero), in its own chunk of `shard_done`."""
    if not 0 < digest < 2 ** 64:
        raise ValueError(must_be("shard digest", "an integer in [1, 2**64)", digest))
    root[DONE][shard] = np.uint64(digest)


def drop_shard_marks(root: zarr.Group, shards) -> None:
    """Forget shards (their data failed a check) and the completion marker, so the next run rewrites them."""
    root.attrs["complete"] = False
    for shard in shards:
        root[DONE][int(shard)] = 0


def has_done_markers(root: zarr.Group, n_shards: int) -> bool:
    """True when `shard_done` exists as this schema writes it: one uint64 checksum per shard."""
    if DONE not in root.array_keys():
        return False
    markers = root[DONE]
    return markers.dtype == np.uint64 and markers.shape == (n_shards,)


def reset_done_markers(root: zarr.Group, n_shards: int) -> None:
    """Recreate `shard_done` as all "not done" (it was deleted or replaced): every shard is rewritten and checked."""
    root.attrs["complete"] = False
    if DONE in root.array_keys():
        del root[DONE]
    root.create_array(DONE, shape=(n_shards,), chunks=(1,), dtype="uint64", fill_value=0, compressors=None)


def shard_digests(root: zarr.Group) -> np.ndarray:
    """(n_shards,) uint64: each shard's recorded checksum, 0 for a shard not done (or whose marker is damaged)."""
    markers = root[DONE]
    try:
        return np.asarray(markers[:]).astype(np.uint64)
    except Exception:  # noqa: BLE001 - a damaged marker chunk: that shard reruns and its marker is rewritten
        out = np.zeros(markers.shape, np.uint64)
        for i in range(markers.shape[0]):
            try:
                out[i] = markers[i]
            except Exception:  # noqa: BLE001 — a damaged marker reads as 'not done': that shard is redone
                pass
        return out


def shards_done(root: zarr.Group) -> np.ndarray:
    """(n_shards,) bool: which shards have finished."""
    return shard_digests(root) != 0


def has_checksums(root: zarr.Group) -> bool:
    """True when the done markers hold checksums (schema 2); schema-1 stores hold a bare 0/1 flag."""
    return DONE in root.array_keys() and root[DONE].dtype == np.uint64


def mark_complete(root: zarr.Group) -> None:
    """The completion marker, written last, once every shard is done."""
    root.attrs.update({"complete": True, "completed_at": now()})


def is_complete(path: Path) -> bool:
    """True when `path` is a store whose completion marker is written."""
    try:
        return bool(open_store(path).attrs.get("complete", False))
    except (FileNotFoundError, ValueError):  # no store, or its root metadata is not a JSON object
        return False
