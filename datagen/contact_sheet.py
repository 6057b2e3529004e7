"""`write_contact_sheet`: a PNG grid of stored images with the stored ee_pixel drawn on each (a visual check).

If the cross does not sit on the end-effector marker, the camera metadata and the images disagree.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

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
    root = open_store(Path(path))
    if "image" not in root.array_keys():
        raise ValueError(must_be("store", "one with images", f"{path} without an `image` array",
                                 "Generate it with images enabled (the default)."))
    total = root["image"].shape[0]
    rows_idx = np.unique(np.linspace(0, total - 1, min(n, total)).round().astype(int))
    images = np.asarray(root["image"].get_orthogonal_selection((rows_idx,)))  # (k, H, W[, 3])
    pixels = np.asarray(root["ee_pixel"].get_orthogonal_selection((rows_idx,)))  # (k, 2) px (u, v)
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
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out_png), grid):
        raise OSError(must_be("out_png", "a writable .png path", str(out_png)))
    return out_png
