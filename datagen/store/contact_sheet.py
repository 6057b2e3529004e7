"""`write_contact_sheet`: a PNG grid of stored images with the stored ee_pixel drawn on each (a visual check).

If the cross does not sit on the end-effector marker, the camera metadata and the images disagree.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from bodyschema.base.outputs import replace_atomically
from bodyschema.datagen.store.schema import open_store
from bodyschema.errors import must_be

MIN_TILE_WIDTH = 160  # px; small images (56 x 80) are upscaled so the marker is visible
LABEL_FONT, LABEL_SCALE = cv2.FONT_HERSHEY_SIMPLEX, 0.45
LABEL_BOX = (24, 24, 24)        # BGR: near-black box, white text: readable over a white hand and a black background
LABEL_TEXT = (255, 255, 255)
TILE_EDGE = (90, 90, 90)        # a grey frame per tile: tiles with black backgrounds do not run into each other


def write_contact_sheet(path: str | Path, out_png: str | Path, n: int = 16) -> Path:
    """Draw `n` evenly spread samples of the store at `path` in a grid; returns `out_png`.

    Each tile shows the image (upscaled with nearest neighbour), a red cross + circle at the stored ee_pixel
    and the sample index, white on a dark box in the corner farthest from the marker (so it hides neither the
    marker nor, usually, the hand). Samples are evenly spaced over the store, so the sheet is deterministic.
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
        cv2.rectangle(bgr, (0, 0), (bgr.shape[1] - 1, bgr.shape[0] - 1), TILE_EDGE, 1)
        centre = None
        if np.isfinite(u) and np.isfinite(v):
            centre = (int(round((u + 0.5) * scale - 0.5)), int(round((v + 0.5) * scale - 0.5)))  # pixel centres
            cv2.drawMarker(bgr, centre, (0, 0, 255), cv2.MARKER_CROSS, 3 * scale, 1)
            cv2.circle(bgr, centre, 2 * scale, (0, 0, 255), 1)
        draw_label(bgr, f"#{idx}", label_corner(centre, bgr.shape[1], bgr.shape[0]))
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


def label_corner(marker: tuple[int, int] | None, width: int, height: int) -> tuple[bool, bool]:
    """(right, bottom): the tile corner farthest from the marker at `marker` (x, y) px; top left without one."""
    if marker is None:
        return False, False
    return marker[0] < width / 2, marker[1] < height / 2


def draw_label(tile: np.ndarray, text: str, corner: tuple[bool, bool]) -> tuple[int, int, int, int]:
    """Write `text` white on a filled dark box in `corner` (right?, bottom?) of `tile` (BGR, in place); returns the
    box (x0, y0, x1, y1) px, inclusive."""
    (w, h), base = cv2.getTextSize(text, LABEL_FONT, LABEL_SCALE, 1)
    pad = 3
    box_w, box_h = w + 2 * pad, h + base + 2 * pad
    x0 = tile.shape[1] - 1 - box_w if corner[0] else 1           # inside the 1 px tile frame
    y0 = tile.shape[0] - 1 - box_h if corner[1] else 1
    x1, y1 = x0 + box_w - 1, y0 + box_h - 1
    cv2.rectangle(tile, (x0, y0), (x1, y1), LABEL_BOX, cv2.FILLED)
    cv2.putText(tile, text, (x0 + pad, y0 + pad + h), LABEL_FONT, LABEL_SCALE, LABEL_TEXT, 1, cv2.LINE_AA)
    return x0, y0, x1, y1


def check_png_path(out_png: str | Path) -> Path:
    """`out_png` as a Path, refused unless it names a .png file (the sheet's only format) and is not a directory."""
    out_png = Path(out_png)
    if out_png.suffix.lower() != ".png" or out_png.is_dir():
        hint = ("It is a directory: name a file in it" if out_png.is_dir()
                else f"For example {out_png.with_suffix('.png').name}")
        raise ValueError(must_be("--out", "a .png file path (the contact sheet is a PNG)", str(out_png),
                                 f"{hint}; nothing was written."))
    return out_png
