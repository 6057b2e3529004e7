"""The read side of a dataset store, for every stage that reads one: check, read, digest and the body it holds.

`check_store` opens a store once and lists every problem of it (`validate_store`'s, and the arrays a reader needs):
training and export read only a store whose problems are empty. What they then read comes from here too: whole
arrays chunk by chunk (`read_arrays`) or rows of one (`read`), the per-sample features, the root attrs as JSON, the
store's digests, and the body (robot, joints and the joint box models scale by) from the root attrs, which import
also reads from an export's copy of them (`attrs_body`).
Two digests, both built on the per-shard checksums that `validate_store` recomputes from the rows: `store_digest`,
the dataset's identity training logs to MLflow (and evaluation records of its targets), and `source_digest`, which
an export records of the store it came from. Each is kept as it was, since recorded values must stay comparable.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import zarr
from tqdm.auto import tqdm

from bodyschema.datagen.store.integrity import data_arrays
from bodyschema.datagen.store.schema import has_checksums, open_store, shard_digests
from bodyschema.errors import must_be

CREATE_HINT = "Create one with `bodyschema datagen --out PATH`."
EDITED_HINT = ("The store's attrs (or an export's copy of them) were edited; regenerate the store with `bodyschema "
               "datagen` (and export it again).")


@dataclass(frozen=True)
class CheckedStore:
    path: Path
    root: zarr.Group | None      # the store opened for reading; None when it cannot be opened (see problems)
    problems: tuple[str, ...]    # empty: complete, valid and holding every array asked for

    @property
    def attrs(self) -> dict[str, Any]:
        return dict(self.root.attrs)


def check_store(path: str | Path, need: tuple[str, ...] = (), *, what: str = "path",
                hints: dict[str, str] | None = None) -> CheckedStore:
    """The store at `path` opened once, with every reason it cannot be read for the arrays `need`: the findings of
    `validate_store`, then each needed array it lacks (`hints`: what to say about one). `what` names the store in
    the problem of a path that holds none (the reader's flag: "data", "STORE")."""
    from bodyschema.datagen.store.validate import validate_open_store

    path = Path(path)
    if not (path / "zarr.json").is_file():
        return CheckedStore(path, None, (must_be(what, "a Zarr v3 dataset store (a directory with zarr.json)",
                                                 str(path), CREATE_HINT),))
    try:
        root = open_store(path)
    except Exception as e:  # noqa: BLE001 - an unopenable store is one problem, as in validate_store
        return CheckedStore(path, None, (str(e),))
    problems = validate_open_store(path, root)
    names = data_arrays(root)
    problems += [must_be(f"data array {name!r}", f"present (arrays: {names})", "missing", (hints or {}).get(name, ""))
                 for name in need if name not in names]
    return CheckedStore(path, root, tuple(problems))


def read_arrays(root: zarr.Group, names: list[str], progress: bool = False) -> dict[str, np.ndarray]:
    """The named arrays, whole, each read one sample-axis chunk at a time (the unit the store was written in)."""
    return {name: _read_chunked(root[name], name, progress) for name in names}


def _read_chunked(array: zarr.Array, name: str, progress: bool) -> np.ndarray:
    n, step = array.shape[0], array.chunks[0]
    out = np.empty(array.shape, dtype=array.dtype)
    starts = range(0, n, step)
    for start in tqdm(starts, desc=f"read {name}", unit="chunk", disable=not progress or len(starts) < 8):
        out[start:start + step] = array[start:start + step]
    return out


def read(root: zarr.Group, name: str, start: int, stop: int) -> np.ndarray:
    """Rows [start, stop) of one array."""
    return np.asarray(root[name][start:stop])


def feature(root: zarr.Group, name: str) -> dict[str, Any]:
    """{dtype, shape (per sample), unit, names} of one array, from the array itself and its attrs."""
    arr = root[name]
    return {"dtype": str(arr.dtype), "shape": [int(s) for s in arr.shape[1:]],
            "unit": str(arr.attrs.get("unit", "")), "names": list(arr.attrs.get("names", []))}


def attrs_json(root: zarr.Group) -> str:
    """The store's root attrs as one JSON text (nested dicts and lists kept as they are)."""
    return json.dumps(dict(root.attrs), sort_keys=True, default=str)


def store_digest(root: zarr.Group) -> str:
    """The dataset's content digest, the same whichever arrays a reader takes: sha256 of every data array's name,
    dtype and shape and of the per-shard checksums datagen recorded (`shard_done`: each covers every array's rows
    of its shard)."""
    _check_checksums(root)
    digest = hashlib.sha256(b"bodyschema-store;")
    for name in data_arrays(root):
        digest.update(f"{name}|{root[name].dtype}|{root[name].shape};".encode())
    digest.update(shard_digests(root).astype("<u8").tobytes())
    return digest.hexdigest()


def source_digest(root: zarr.Group) -> str:
    """sha256 of the store's root attrs and its shards' checksums: what an export records of the store it read."""
    _check_checksums(root)
    h = hashlib.sha256(attrs_json(root).encode())
    h.update(shard_digests(root).tobytes())
    return h.hexdigest()


def _check_checksums(root: zarr.Group) -> None:
    """The digests stand on the per-shard checksums: a store without them (schema 1) has no digest."""
    if not has_checksums(root):
        raise ValueError(must_be("the store", "one with per-shard checksums (schema 2)", "none",
                                 "`bodyschema validate` it; regenerate with `bodyschema datagen --overwrite`."))


def store_body(root: zarr.Group) -> dict[str, Any]:
    """`attrs_body` of an open store."""
    return attrs_body(dict(root.attrs), root["q"].shape[1])


def attrs_body(attrs: dict[str, Any], q_width: int) -> dict[str, Any]:
    """The body of a store's samples from its root attrs (or an export's copy of them), as `BodySpec.to_dict` of a
    shipped robot: robot, joint names (one per column of q) and the sampled joint box q_low, q_high (rad) a model
    of it scales by (attrs sampling_ranges; never a stand-in: `validate_store` requires them)."""
    names = list(attrs["joint_names"])
    if len(names) != q_width:
        raise ValueError(must_be("data attrs['joint_names']", f"one name per column of q ({q_width})", names,
                                 EDITED_HINT))
    box = _box(attrs.get("sampling_ranges"))
    if box is None or box.shape != (q_width, 2):
        raise ValueError(must_be("data attrs['sampling_ranges']", f"({q_width}, 2) (lo, hi) rad, one per column of q",
                                 attrs.get("sampling_ranges"), EDITED_HINT))
    return {"robot": str(attrs["robot"]), "joint_names": names, "q_low": box[:, 0].tolist(),
            "q_high": box[:, 1].tolist()}


def _box(ranges) -> np.ndarray | None:
    try:
        return None if ranges is None else np.asarray(ranges, dtype=float)
    except (TypeError, ValueError):       # ragged or not numbers
        return None
