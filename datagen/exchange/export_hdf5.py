"""A dataset store as one HDF5 file (h5py), readable without bodyschema, zarr or torch.

Layout:
    /<array>          one dataset per data array (q, ee_xyz, ee_pixel, jacobian, image, qvel, touch, episode, t,
                      target: a babbling store's servo targets),
                      the store's dtype and shape (N, *per-sample), gzip-compressed in the store's row chunks;
                      attrs: unit, names (axis names, e.g. the joint order is the body's), shape (per sample)
    /body             attrs: robot, joint_names, q_low, q_high (rad): the joint scaling a model of it uses
    / (root)          attrs: every root attr of the store (JSON text in `store_attrs`, scalars also one by one),
                      format = "bodyschema-hdf5", format_version
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import zarr

from bodyschema.datagen.store.integrity import data_arrays
from bodyschema.datagen.store.reader import attrs_json, feature, read, store_body
from bodyschema.datagen.store.rows import row_blocks

FORMAT, FORMAT_VERSION = "bodyschema-hdf5", 1
SIZE_FACTOR = 1.5                       # output / the store's compressed bytes: 1.4 measured (1500 planar2 images)
COMPRESSION = {"compression": "gzip", "compression_opts": 1}   # fast; any HDF5 reader decodes gzip


def write_hdf5(root: zarr.Group, out: Path) -> None:
    import h5py

    with _FailedWritesDropped(out) as sink:
        with h5py.File(sink, "w") as f:
            f.attrs.update({"format": FORMAT, "format_version": FORMAT_VERSION, "store_attrs": attrs_json(root)})
            for key, value in dict(root.attrs).items():
                if isinstance(value, (str, int, float, bool)):     # nested ones are in store_attrs only
                    f.attrs[key] = value
            spec = store_body(root)
            group = f.create_group("body")
            for key, value in spec.items():
                group.attrs[key] = value
            for name in data_arrays(root):
                _copy_array(f, root, name, sink.raise_failure)
        sink.raise_failure()                                     # one in the writes of the close


class _FailedWritesDropped:
    """The file HDF5 writes through (h5py's "fileobj" driver). A failed write (a full disk) is recorded and every
    later write dropped, so HDF5 never sees it: with the default driver it retried the writes in destructors,
    printed tracebacks and crashed the process. `raise_failure` raises the recorded error once HDF5 is out of it."""

    def __init__(self, path: Path):
        self.raw = open(path, "w+b", buffering=0)    # unbuffered: a write fails in `write`, not in a later seek
        self.failure: OSError | None = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.raw.close()

    def raise_failure(self) -> None:
        if self.failure is not None:
            raise self.failure

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        try:
            while self.failure is None and view:
                view = view[self.raw.write(view):]
        except OSError as e:
            self.failure = e
        return len(data)

    def read(self, size: int) -> bytes:
        data = self.raw.read(size)
        return data + bytes(size - len(data))        # past the end reads as zeros (as HDF5's own sec2 driver)

    def truncate(self, size: int) -> None:
        if self.failure is None:
            try:
                self.raw.truncate(size)
            except OSError as e:
                self.failure = e

    def seek(self, offset: int, whence: int = 0) -> int:
        return self.raw.seek(offset, whence)

    def tell(self) -> int:
        return self.raw.tell()

    def flush(self) -> None:
        pass                                         # unbuffered


def _copy_array(f, root: zarr.Group, name: str, check: Callable[[], None]) -> None:
    import h5py

    arr, feat = root[name], feature(root, name)
    n = arr.shape[0]
    chunks = (min(n, arr.chunks[0]), *arr.shape[1:]) if n else None
    ds = f.create_dataset(name, shape=arr.shape, dtype=arr.dtype, chunks=chunks, **(COMPRESSION if n else {}))
    ds.attrs.update({"unit": feat["unit"], "shape": feat["shape"],
                     "names": np.array(feat["names"], dtype=h5py.string_dtype())})
    for start, stop in row_blocks(n):
        ds[start:stop] = read(root, name, start, stop)
        check()                                       # stop at a failed write, not after compressing the rest
