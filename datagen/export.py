"""`export_dataset(store, out, to)`: a Zarr dataset store as another format ("hdf5" or "lerobot"), checked first.

What every format gets from here, so the writers only lay it out: the store validated (an incomplete or damaged
store is refused with every problem listed, as `bodyschema validate` would), its data arrays with their
per-sample shape, unit and axis names, the body (robot, joint names, the sampled joint ranges the models scale
by: `training.data.body_from_attrs`'s values), the root attrs as JSON, and a writer that builds the output
beside its final path and renames it into place (datagen/outputs.py): a killed export never leaves a half-written
OUT, and --overwrite replaces only a previous export of the same format, never the store itself.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import zarr

from bodyschema.datagen.outputs import check_out, write_atomically
from bodyschema.datagen.store import DONE, open_store, shard_digests
from bodyschema.errors import must_be

FORMATS = ("hdf5", "lerobot")
ROWS_PER_READ = 4096          # rows read from the store at a time: images of 4096 × 56 × 80 are 18 MB


def export_dataset(store: str | Path, out: str | Path, to: str, *, overwrite: bool = False) -> Path:
    """Write the store at `store` to `out` in format `to`; returns `out`."""
    if to not in FORMATS:
        raise ValueError(must_be("--to", f"one of {FORMATS}", to))
    store, out = Path(store), Path(out)
    if to == "hdf5":
        from bodyschema.datagen.export_hdf5 import FORMAT, SIZE_FACTOR, write_hdf5 as write
    else:
        from bodyschema.datagen.export_lerobot import FORMAT, SIZE_FACTOR, write_lerobot as write
    check_out(out, FORMAT, overwrite, [store])         # before the validation, which reads every chunk
    root = checked_store(store)
    source = {"store": str(store.resolve()), "digest": source_digest(root)}
    return write_atomically(out, lambda tmp: write(root, tmp), overwrite, kind=FORMAT, inputs=[store],
                            need_bytes=int(SIZE_FACTOR * stored_bytes(root)), source=source)


def checked_store(path: Path) -> zarr.Group:
    """The open store, refused (all problems listed) unless `validate_store` finds it complete and intact."""
    from bodyschema.datagen.validate import validate_store

    if not path.exists():
        raise FileNotFoundError(must_be("STORE", "an existing .zarr store", str(path),
                                        "Create one with `bodyschema datagen --out PATH`."))
    root = open_store(path)
    problems = validate_store(path)
    if problems:
        raise ValueError(must_be("STORE", "a complete, valid store", f"{len(problems)} problem(s) in {path}",
                                 "See `bodyschema validate " + str(path) + "`:\n - " + "\n - ".join(problems)))
    return root


def source_digest(root: zarr.Group) -> str:
    """sha256 of the store's root attrs and its shards' checksums (which `validate_store` checked against the rows)."""
    h = hashlib.sha256(attrs_json(root).encode())
    h.update(shard_digests(root).tobytes())
    return h.hexdigest()


def stored_bytes(root: zarr.Group) -> int:
    """Bytes the data arrays take in the store (compressed): the base of an export's size estimate."""
    return sum(int(root[name].nbytes_stored()) for name in data_arrays(root))


# ---- what the writers share ---------------------------------------------------------------------------------
def data_arrays(root: zarr.Group) -> list[str]:
    """The data arrays (everything but the bookkeeping `shard_done`), sorted."""
    return sorted(name for name in root.array_keys() if name != DONE)


def feature(root: zarr.Group, name: str) -> dict[str, Any]:
    """{dtype, shape (per sample), unit, names} of one array, from the array itself and its attrs."""
    arr = root[name]
    return {"dtype": str(arr.dtype), "shape": [int(s) for s in arr.shape[1:]],
            "unit": str(arr.attrs.get("unit", "")), "names": list(arr.attrs.get("names", []))}


def body(attrs: dict[str, Any]) -> dict[str, Any]:
    """The model body spec of the store: robot, joint names and the sampled ranges in rad (BodySpec.to_dict)."""
    ranges = attrs.get("sampling_ranges") or attrs["joint_limits"]
    return {"robot": str(attrs["robot"]), "joint_names": list(attrs["joint_names"]),
            "q_low": [float(r[0]) for r in ranges], "q_high": [float(r[1]) for r in ranges]}


def attrs_json(root: zarr.Group) -> str:
    """The store's root attrs as one JSON text (nested dicts and lists kept as they are)."""
    return json.dumps(dict(root.attrs), sort_keys=True, default=str)


def row_blocks(n: int, step: int | None = None):
    """(start, stop) ranges covering [0, n) in steps of `step` rows (default ROWS_PER_READ)."""
    step = step or ROWS_PER_READ
    return ((start, min(n, start + step)) for start in range(0, n, step))


def read(root: zarr.Group, name: str, start: int, stop: int) -> np.ndarray:
    return np.asarray(root[name][start:stop])
