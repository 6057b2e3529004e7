"""A dataset store as one HDF5 file (h5py), readable without bodyschema, zarr or torch.

Layout:
    /<array>          one dataset per data array (q, ee_xyz, ee_pixel, jacobian, image, qvel, touch, episode, t),
                      the store's dtype and shape (N, *per-sample), gzip-compressed in the store's row chunks;
                      attrs: unit, names (axis names, e.g. the joint order is the body's), shape (per sample)
    /body             attrs: robot, joint_names, q_low, q_high (rad): the joint scaling a model of it uses
    / (root)          attrs: every root attr of the store (JSON text in `store_attrs`, scalars also one by one),
                      format = "bodyschema-hdf5", format_version
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import zarr

from bodyschema.datagen.export import attrs_json, body, data_arrays, feature, read, row_blocks

FORMAT, FORMAT_VERSION = "bodyschema-hdf5", 1
COMPRESSION = {"compression": "gzip", "compression_opts": 1}   # fast; any HDF5 reader decodes gzip


def write_hdf5(root: zarr.Group, out: Path) -> None:
    import h5py

    with h5py.File(out, "w") as f:
        f.attrs.update({"format": FORMAT, "format_version": FORMAT_VERSION, "store_attrs": attrs_json(root)})
        for key, value in dict(root.attrs).items():
            if isinstance(value, (str, int, float, bool)):     # nested ones are in store_attrs only
                f.attrs[key] = value
        spec = body(dict(root.attrs))
        group = f.create_group("body")
        for key, value in spec.items():
            group.attrs[key] = value
        for name in data_arrays(root):
            _copy_array(f, root, name)


def _copy_array(f, root: zarr.Group, name: str) -> None:
    import h5py

    arr, feat = root[name], feature(root, name)
    n = arr.shape[0]
    chunks = (min(n, arr.chunks[0]), *arr.shape[1:]) if n else None
    ds = f.create_dataset(name, shape=arr.shape, dtype=arr.dtype, chunks=chunks, **(COMPRESSION if n else {}))
    ds.attrs.update({"unit": feat["unit"], "shape": feat["shape"],
                     "names": np.array(feat["names"], dtype=h5py.string_dtype())})
    for start, stop in row_blocks(n):
        ds[start:stop] = read(root, name, start, stop)
