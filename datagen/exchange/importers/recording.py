"""`Recording`: what a source reader hands the writer, in the source's own terms (before the body is applied).

A reader only lays out what it found; units, joint order, images and ranges are judged later, in one place
(body.py, images.py, writer.py), so every format gets the same checks and the same house errors.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bodyschema.errors import must_be

# Arrays a recording may carry besides q and images, with the dtype the store keeps (store.features).
EXTRA_ARRAYS = {"ee_xyz": "float32", "ee_rot": "float32", "ee_pixel": "float32", "jacobian": "float32",
                "qvel": "float32", "touch": "float32", "episode": "int32", "t": "float32", "target": "float32"}


@dataclass
class Recording:
    """One recording: N frames of joint angles, optional images and readings, and where they came from."""

    q: np.ndarray                              # (N, K) float64, in the recorded unit, columns as `columns`
    columns: tuple[str, ...] | None            # the name of each q column; None: unnamed (the body's order)
    images: list[np.ndarray] | None = None     # N images (H, W[, C]) uint8 (sizes may differ before images.py)
    image_names: list[str] = field(default_factory=list)   # per image, for error messages (file name, frame)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)   # EXTRA_ARRAYS found: (N, ...) in store units
    unit: str | None = None                    # "rad" when the source states it; None: --angles must say
    attrs: dict[str, Any] = field(default_factory=dict)   # a bodyschema export's store attrs ({} otherwise)
    files: list[Path] = field(default_factory=list)       # every file read (the source digest)
    params: dict[str, Any] = field(default_factory=dict)  # how it was read (format, keys): sampler_params
    dropped: dict[str, str] = field(default_factory=dict)  # each feature of the source not imported → why (said once)

    def __post_init__(self) -> None:
        n = len(self.q)
        if n == 0:
            raise ValueError(must_be("the recording", "at least one frame", "0 frames"))
        if self.images is not None and len(self.images) != n:
            raise ValueError(must_be("joint-angle rows", f"one per image ({len(self.images)} images)",
                                     f"{n} rows", "Each image needs exactly one row of angles, in the same order."))
        for name, values in self.arrays.items():
            if len(values) != n:
                raise ValueError(must_be(f"{name}", f"one row per frame ({n})", f"{len(values)} rows"))


def check_finite(name: str, values: np.ndarray, labels: list[str] | None = None) -> None:
    """The house error naming the first row (and column) holding NaN or inf."""
    bad = ~np.isfinite(values.reshape(len(values), -1))
    if bad.any():
        row, col = (int(i[0]) for i in np.nonzero(bad))
        where = labels[row] if labels else f"row {row}"
        raise ValueError(must_be(name, "finite in every row", f"NaN or inf at {where}, column {col} "
                                 f"({int(bad.any(axis=1).sum())} rows)", "Drop or repair those frames."))


def source_sha256(files: list[Path], root: Path) -> str:
    """sha256 of every file read: each path relative to the source, then its bytes, in sorted order."""
    digest = hashlib.sha256(b"bodyschema-import;")
    for path in sorted(set(files)):
        rel = path.relative_to(root).as_posix() if path != root else path.name
        digest.update(f"{rel};".encode())
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()
