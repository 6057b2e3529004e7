"""The shared writer of every importer: arrays and attrs → a complete, validated store, or nothing at all.

The store is written as datagen writes one (store.py: the same features, chunks of `chunk_len` rows, each chunk's
checksum in its done marker, the completion marker last) into a temporary sibling of OUT; `validate_store` must
find no problem there before it is renamed into place. Any failure removes the sibling: OUT is either the old
state or the whole new store.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bodyschema.base import modalities
from bodyschema.base.outputs import write_atomically
from bodyschema.datagen.store.integrity import shard_digest
from bodyschema.datagen.store.schema import (
    StoreWriteError,
    create_store,
    features,
    mark_complete,
    mark_shard_done,
    write_shard,
)
from bodyschema.errors import must_be

ROWS_WITH_IMAGES, ROWS_WITHOUT = 512, 16384   # rows per chunk, as datagen's default shards
KIND = "bodyschema-import"                    # the outputs.py marker: --overwrite replaces only an earlier import


def store_features(arrays: dict[str, np.ndarray]) -> dict[str, dict[str, Any]]:
    """The schema's features of the arrays present (store.features, restricted to them)."""
    cameras = modalities.images_in(arrays)
    image_shape = arrays[cameras[0]].shape[1:] if cameras else None
    full = features(arrays["q"].shape[1], image_shape, arrays, True)    # the sensors: those of the arrays
    return {name: spec for name, spec in full.items() if name in arrays}


def chunk_rows(arrays: dict[str, np.ndarray]) -> int:
    return ROWS_WITH_IMAGES if modalities.images_in(arrays) else ROWS_WITHOUT


def write_store(out: Path, arrays: dict[str, np.ndarray], attrs: dict[str, Any], overwrite: bool,
                source: Path) -> Path:
    """Write `arrays` (each (N, ...) in the store dtype) with `attrs` to `out`, validated, atomically; OUT never is,
    holds or lies inside the source, and --overwrite replaces only an earlier import."""
    need = sum(values.nbytes for values in arrays.values())         # uncompressed: an upper bound
    return write_atomically(Path(out), lambda tmp: _write(tmp, arrays, attrs), overwrite, kind=KIND,
                            inputs=[source], need_bytes=need, source=attrs["source"])


def _write(path: Path, arrays: dict[str, np.ndarray], attrs: dict[str, Any]) -> None:
    from bodyschema.datagen.store.validate import validate_store

    n, step = len(arrays["q"]), int(attrs["chunk_len"])
    try:
        root = create_store(path, attrs["features"], n, step, attrs["n_shards"], attrs)
        for shard, start in enumerate(range(0, n, step)):
            write_shard(root, start, {name: values[start:start + step] for name, values in arrays.items()})
            mark_shard_done(root, shard, shard_digest(root, start, min(n, start + step)))
        mark_complete(root)
    except OSError as e:
        raise StoreWriteError.from_os_error(path, e) from e
    problems = [_about_the_recording(p) for p in validate_store(path)]
    if problems:
        raise ValueError(must_be("the imported store", "valid", f"{len(problems)} problem(s)",
                                 "Nothing was written. Fix the recording:\n - " + "\n - ".join(problems)))


def _about_the_recording(problem: str) -> str:
    """A validate line without its datagen hint (rerun or regenerate): for an import the recording is at fault."""
    from bodyschema.datagen.store import remedies

    for hint in (remedies.RESUME_HINT, remedies.REPAIR_HINT, remedies.REGENERATE_HINT, remedies.EDITED_HINT):
        problem = problem.replace(" " + hint, "").replace(hint, "")
    return problem
