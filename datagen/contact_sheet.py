"""`write_contact_sheet`: a PNG grid of stored images with the stored ee_pixel drawn on each (a visual check).

If the cross does not sit on the end-effector marker, the camera metadata and the images disagree.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from bodyschema.datagen.outputs import replace_atomically
from bodyschema.datagen.store import open_store
from bodyschema.errors import must_be

MIN_TILE_WIDTH = 160  # px; small images (56 x 80) are upscaled so the marker is visible


def write_contact_sheet(path: str | Path, out_png: str | Path, n: int = 16) -> Path:
    """Draw `n` evenly spread samples of the store at `path` in a grid; returns `out_png`.

    Each tile shows the image (upscaled with nearest neighbour), a red cross + circle at the stored ee_pixel
    and the sample index. Samples are evenly spaced over the store, so the sheet is deterministic.
    """
    if not isinstance(n, int) or n < 1:
        raise ValueError(must_be("n", "an integer >= 1", n))
    out_png = check_png_path(out_png)
    root = open_store(Path(path))
    if "image" not in root.array_keys():
        raise ValueError(must_be("store", "one with images", f"{path} without an `image` array",
                                 "Generate it with images enabled (the default)."))
    total = root["image"].shape[0]
    rows_idx = np.unique(np.linspace(0, total - 1, min(n, total)).round().astype(int))
    images = np.asarray(root["image"].get_orthogonal_selection((rows_idx,)))  # (k, H, W[, 3])
    pixels = (np.asarray(root["ee_pixel"].get_orthogonal_selection((rows_idx,))) if "ee_pixel" in root.array_keys()
              else np.full((len(rows_idx), 2), np.nan))  # (k, 2) px (u, v); imported recordings may have none
    h, w = images.shape[1:3]
    scale = max(1, math.ceil(MIN_TILE_WIDTH / w))
    tiles = []
    for idx, img, (u, v) in zip(rows_idx, images, pixels):
        bgr = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        bgr = cv2.resize(bgr, (w * scale, h * scale), interpolation=cv2.INTER_NEAREST)
        if np.isfinite(u) and np.isfinite(v):
            centre = (int(round((u + 0.5) * scale - 0.5)), int(round((v + 0.5) * scale - 0.5)))  # pixel centres
            cv2.drawMarker(bgr, centre, (0, 0, 255), cv2.MARKER_CROSS, 3 * scale, 1)
            cv2.circle(bgr, centre, 2 * scale, (0, 0, 255), 1)
        cv2.putText(bgr, str(idx), (3, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 255, 0), 1, cv2.LINE_AA)
        tiles.append(bgr)
    cols = math.ceil(math.sqrt(len(tiles)))
    blank = np.zeros_like(tiles[0])
    tiles += [blank] * (-len(tiles) % cols)
    grid = np.vstack([np.hstack(tiles[r:r + cols]) for r in range(0, len(tiles), cols)])
    ok, png = cv2.imencode(".png", grid)
    if not ok:
        raise ValueError(must_be("the contact sheet", "encodable as PNG", f"array {grid.shape} {grid.dtype}"))
    out_png.parent.mkdir(parents=True, exist_ok=True)
    replace_atomically(out_png.resolve(), lambda tmp: tmp.write_bytes(png.tobytes()), png.nbytes)   # never half a PNG
    return out_png


def check_png_path(out_png: str | Path) -> Path:
    """`out_png` as a Path, refused unless it names a .png file (the sheet's only format) and is not a directory."""
    out_png = Path(out_png)
    if out_png.suffix.lower() != ".png" or out_png.is_dir():
        hint = ("It is a directory: name a file in it" if out_png.is_dir()
                else f"For example {out_png.with_suffix('.png').name}")
        raise ValueError(must_be("--out", "a .png file path (the contact sheet is a PNG)", str(out_png),
                                 f"{hint}; nothing was written."))
    return out_png
