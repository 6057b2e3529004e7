"""`export_dataset(store, out, to)`: a Zarr dataset store as another format ("hdf5" or "lerobot"), checked first.

What every format gets from here, so the writers only lay it out: the store checked (an incomplete or damaged
store is refused with every problem listed, as `bodyschema validate` would), its size and the row blocks to read it
in, and a writer that builds the output beside its final path and renames it into place (base/outputs.py): a
killed export never leaves a half-written OUT, and --overwrite replaces only a previous export of the same format,
never the store itself. What they read (arrays, features, attrs, the body the models of it scale by) comes from
`datagen.store.reader`, the reader training uses.
"""

from __future__ import annotations

from pathlib import Path

import zarr

from bodyschema.base.outputs import check_out, write_atomically
from bodyschema.datagen.exchange import export_hdf5, export_lerobot
from bodyschema.datagen.store.integrity import data_arrays
from bodyschema.datagen.store.reader import CREATE_HINT, check_store, source_digest
from bodyschema.errors import must_be

FORMATS = ("hdf5", "lerobot")
# format → (its output kind, its size factor over the stored bytes, its writer)
WRITERS = {"hdf5": (export_hdf5.FORMAT, export_hdf5.SIZE_FACTOR, export_hdf5.write_hdf5),
           "lerobot": (export_lerobot.FORMAT, export_lerobot.SIZE_FACTOR, export_lerobot.write_lerobot)}


def export_dataset(store: str | Path, out: str | Path, to: str, *, overwrite: bool = False) -> Path:
    """Write the store at `store` to `out` in format `to`; returns `out`."""
    if to not in FORMATS:
        raise ValueError(must_be("--to", f"one of {FORMATS}", to))
    store, out = Path(store), Path(out)
    kind, size_factor, write = WRITERS[to]
    check_out(out, kind, overwrite, [store])           # before the validation, which reads every chunk
    root = checked_store(store)
    source = {"store": str(store.resolve()), "digest": source_digest(root)}
    return write_atomically(out, lambda tmp: write(root, tmp), overwrite, kind=kind, inputs=[store],
                            need_bytes=int(size_factor * stored_bytes(root)), source=source)


def checked_store(path: Path) -> zarr.Group:
    """The open store, refused (all problems listed) unless it is complete and intact (`check_store`)."""
    if not path.exists():
        raise FileNotFoundError(must_be("STORE", "an existing .zarr store", str(path), CREATE_HINT))
    store = check_store(path, what="STORE")
    if store.problems:
        raise ValueError(must_be("STORE", "a complete, valid store", f"{len(store.problems)} problem(s) in {path}",
                                 "See `bodyschema validate " + str(path) + "`:\n - " + "\n - ".join(store.problems)))
    return store.root


def stored_bytes(root: zarr.Group) -> int:
    """Bytes the data arrays take in the store (compressed): the base of an export's size estimate."""
    return sum(int(root[name].nbytes_stored()) for name in data_arrays(root))
