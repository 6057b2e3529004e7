"""A folder of camera images plus a CSV of joint angles, one row per image: the layout labs record.

    recording/img0.png img1.png … img10.png angles.csv

The CSV has a header naming the joints (any order, matched to the body's names) or no header (columns in the
body's joint order). Optional columns: `image` (or `file`, `filename`: the image of the row, relative to the
folder; without it rows go with the images in natural order, img2 before img10), `t` (or `time`, `timestamp`: s)
and `episode`. Any other named column is taken as a joint, and a name the body does not have is refused.
"""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path, PurePath

import numpy as np

from bodyschema.datagen.exchange.importers.recording import Recording
from bodyschema.errors import must_be

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")
FILE_COLUMNS = ("image", "file", "filename")
TIME_COLUMNS = ("t", "time", "timestamp")


def read_folder(folder: Path, csv_path: Path | None, images: bool) -> Recording:
    csv_path = csv_path or _the_csv(folder)
    header, rows = _read_csv(csv_path)
    files = [csv_path]
    columns = header or [f"column {i}" for i in range(len(rows[0]))]
    special = {c for c in columns if c.lower() in (*FILE_COLUMNS, *TIME_COLUMNS, "episode")}
    joint_cols = [i for i, c in enumerate(columns) if c not in special]
    q = _numbers(rows, joint_cols, columns, csv_path)                                # (N, K) recorded unit
    arrays = {}
    for i, c in enumerate(columns):
        if c.lower() in TIME_COLUMNS:
            arrays["t"] = _numbers(rows, [i], columns, csv_path)[:, 0].astype(np.float32)
        elif c.lower() == "episode":
            arrays["episode"] = _numbers(rows, [i], columns, csv_path)[:, 0]   # whole numbers checked in run.py
    image_paths: list[Path] = []
    if images:
        file_col = next((i for i, c in enumerate(columns) if c.lower() in FILE_COLUMNS), None)
        image_paths = _listed(folder, rows, file_col) if file_col is not None else _in_order(folder)
        files += image_paths
    frames = [_read_image(p) for p in image_paths] if images else None
    return Recording(q, tuple(columns[i] for i in joint_cols) if header else None, frames,
                     [p.name for p in image_paths], arrays, files=files,
                     params={"format": "folder", "csv": csv_path.name, "images": len(image_paths)})


def _the_csv(folder: Path) -> Path:
    found = sorted(folder.glob("*.csv"))
    if len(found) != 1:
        raise FileNotFoundError(must_be(f"CSV files in {folder}", "exactly one (the joint angles)",
                                        [p.name for p in found], "Name it with --csv PATH."))
    return found[0]


def _read_csv(path: Path) -> tuple[list[str] | None, list[list[str]]]:
    """(header or None, data rows); a header is a first row holding a cell that is not a number."""
    if not path.is_file():
        raise FileNotFoundError(must_be("--csv", "an existing CSV file", str(path)))
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = [[cell.strip() for cell in row] for row in csv.reader(f) if any(cell.strip() for cell in row)]
    except UnicodeDecodeError as e:
        raise ValueError(must_be(f"CSV {path.name}", "UTF-8 text", f"byte {e.object[e.start:e.start + 1].hex()} at "
                                 f"offset {e.start} (not UTF-8; latin-1?)", "Save it as UTF-8.")) from None
    except csv.Error as e:
        raise ValueError(must_be(f"CSV {path.name}", "comma-separated text", str(e))) from None
    if not rows:
        raise ValueError(must_be(f"CSV {path.name}", "at least one row of joint angles", "an empty file"))
    header = rows[0] if any(not _is_number(c) for c in rows[0]) else None
    if header:
        _check_header(header, path)
    data = rows[1:] if header else rows
    width = len(rows[0])
    for i, row in enumerate(data):
        if len(row) != width:
            raise ValueError(must_be(f"CSV {path.name} row {i + 1}", f"{width} cells like the first row",
                                     f"{len(row)} cells"))
    if not data:
        raise ValueError(must_be(f"CSV {path.name}", "at least one row of joint angles", "a header only"))
    return header, data


def _check_header(header: list[str], path: Path) -> None:
    """Each column named once: a joint named twice, or two columns of one role (image/file, t/time), is refused."""
    roles = [_role(c) for c in header]
    twice = sorted({c for c, r in zip(header, roles) if roles.count(r) > 1})
    if twice:
        raise ValueError(must_be(f"the header of CSV {path.name}", "each joint and column named once",
                                 f"{twice} in {header}", "Drop or rename the repeated column; nothing is dropped "
                                 "silently."))


def _role(column: str) -> str:
    low = column.lower()
    return ("image" if low in FILE_COLUMNS else "t" if low in TIME_COLUMNS else "episode" if low == "episode"
            else f"joint {column}")


def _is_number(cell: str) -> bool:
    try:
        float(cell)
        return True
    except ValueError:
        return False


def _numbers(rows: list[list[str]], cols: list[int], columns: list[str], path: Path) -> np.ndarray:
    out = np.empty((len(rows), len(cols)))
    for r, row in enumerate(rows):
        for k, c in enumerate(cols):
            try:
                out[r, k] = float(row[c])
            except ValueError:
                raise ValueError(must_be(f"CSV {path.name} row {r + 1}, column {columns[c]!r}", "a number",
                                         row[c])) from None
    return out


def _natural(name: str) -> list:
    """Sort key: digit runs as numbers (img2 before img10)."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def _in_order(folder: Path) -> list[Path]:
    return sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()),
                  key=lambda p: _natural(p.name))


def _listed(folder: Path, rows: list[list[str]], col: int) -> list[Path]:
    for r, row in enumerate(rows):
        cell = PurePath(row[col])
        if cell.is_absolute() or ".." in PurePath(os.path.normpath(cell)).parts:
            raise ValueError(must_be(f"the image of CSV row {r + 1}", f"a path inside the recording folder {folder}",
                                     row[col], "Name each image relative to the folder, without '..'; copy images "
                                     "from elsewhere into it."))
    paths = [folder / row[col] for row in rows]
    missing = [str(p.name) for p in paths if not p.is_file()]
    if missing:
        raise FileNotFoundError(must_be("the images the CSV names", f"files in {folder}",
                                        f"{len(missing)} missing, first {missing[0]!r}"))
    return paths


def _read_image(path: Path) -> np.ndarray:
    """(H, W) or (H, W, 3) RGB uint8; a 16-bit or unreadable file is the house error."""
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError(must_be(f"image {path.name}", "a readable image file (PNG, JPEG, ...)", "unreadable"))
    return from_opencv(image, path.name)


def from_opencv(image: np.ndarray, label: str) -> np.ndarray:
    """An image as OpenCV decodes it (BGR[A] or gray) → (H, W) or (H, W, 3) RGB uint8."""
    import cv2

    if image.dtype != np.uint8:
        raise ValueError(must_be(f"image {label}", "8-bit (uint8)", str(image.dtype),
                                 "Convert it to 8 bits per channel (e.g. PNG 8-bit)."))
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2RGB if image.shape[2] == 4 else cv2.COLOR_BGR2RGB
        return cv2.cvtColor(image, code)
    return image
