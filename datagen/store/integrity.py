"""Shard integrity: which chunk files a store must hold, each shard's checksum, and which done shards fail them.

A shard (rows [i·chunk_len, (i+1)·chunk_len)) owns chunk row i of every data array. Zarr reads a missing chunk
as its fill value and says nothing, so completeness is proven two ways: every expected chunk key is on disk, and
the checksum recorded in the shard's done marker (`shard_digest` of its rows as stored, computed right after the
write) equals the one recomputed now. `datagen` rewrites the shards that fail; `validate_store` reports them.
"""

from __future__ import annotations

import hashlib
import itertools
from pathlib import Path

import numpy as np
import zarr

from bodyschema.datagen.store.schema import DONE, has_checksums, shard_digests


def data_arrays(root: zarr.Group) -> list[str]:
    """The data arrays of a store, sorted (everything but the bookkeeping `shard_done`)."""
    return sorted(name for name in root.array_keys() if name != DONE)


def block_digest(block: dict[str, np.ndarray]) -> int:
    """64-bit checksum (sha256, first 8 bytes, never 0) of named arrays: names, dtypes, shapes and bytes."""
    h = hashlib.sha256()
    for name in sorted(block):
        values = np.ascontiguousarray(block[name])
        h.update(f"{name}:{values.dtype.str}:{values.shape};".encode())
        h.update(memoryview(values).cast("B"))
    return int.from_bytes(h.digest()[:8], "little") or 1  # 0 means "not done"


def read_rows(root: zarr.Group, names: list[str], start: int, stop: int) -> dict[str, np.ndarray]:
    """Rows [start, stop) of each named array, as stored (raises on an undecodable chunk)."""
    return {name: np.asarray(root[name][start:stop]) for name in names}


def shard_digest(root: zarr.Group, start: int, stop: int) -> int:
    """The checksum of rows [start, stop) of every data array, read back through the codecs."""
    return block_digest(read_rows(root, data_arrays(root), start, stop))


def chunk_keys(arr: zarr.Array, row_chunk: int) -> list[str]:
    """The store keys (relative to the array) of the chunks holding sample-chunk `row_chunk` of `arr`."""
    rest = [range(c) for c in arr.cdata_shape[1:]]
    return [arr.metadata.encode_chunk_key(coords) for coords in itertools.product([row_chunk], *rest)]


def missing_chunks(path: Path, root: zarr.Group, names: list[str]) -> dict[str, list[int]]:
    """{array: sorted sample-chunk indices with a chunk file missing on disk} for the named arrays."""
    out = {}
    for name in names:
        arr = root[name]
        folder = Path(path) / arr.path
        on_disk = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}
        gone = [i for i in range(arr.cdata_shape[0]) if not all(k in on_disk for k in chunk_keys(arr, i))]
        if gone:
            out[name] = gone
    return out


def clear_shard(path: Path, root: zarr.Group, index: int) -> None:
    """Delete shard `index`'s chunk files in every data array, so a damaged leftover is never read or merged."""
    for name in data_arrays(root):
        arr = root[name]
        for key in chunk_keys(arr, index):  # sample-chunk i is shard i's (chunk_len = shard rows)
            (Path(path) / arr.path / key).unlink(missing_ok=True)


def failing_shards(path: Path, root: zarr.Group) -> dict[int, str]:
    """{shard: why} for every done shard whose chunks are missing, unreadable or differ from its checksum."""
    if not has_checksums(root):
        return {}
    names, digests = data_arrays(root), shard_digests(root)
    if not names:
        return {}
    first = root[names[0]]
    step, n = int(root.attrs.get("chunk_len") or first.chunks[0]), first.shape[0]
    faults = {i: f"{name} chunk missing" for name, rows in missing_chunks(path, root, names).items()
              for i in rows if digests[i]}
    for i in np.flatnonzero(digests):
        if int(i) in faults:
            continue
        start, stop = int(i) * step, min(n, (int(i) + 1) * step)
        try:
            digest = block_digest(read_rows(root, names, start, stop))
        except Exception as e:  # noqa: BLE001 - any decoding failure (Zstd, size) is a damaged chunk
            faults[int(i)] = f"unreadable ({type(e).__name__})"
            continue
        if digest != int(digests[i]):
            faults[int(i)] = "checksum mismatch"
    return faults
