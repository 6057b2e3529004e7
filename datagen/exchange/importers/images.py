"""Recorded frames → one (N, H, W[, 3]) uint8 array: crop, resize, grayscale, and one size and channel count for all.

Order: crop (top, left, height, width) first, in the recorded pixels, then resize to (H, W) with area averaging
(what shrinking a camera frame needs; no aliasing), then grayscale with the BT.601 luma datagen renders with.
"""

from __future__ import annotations

import numpy as np

from bodyschema.datagen.exchange.importers.config import IMAGE_SIDE_RANGE
from bodyschema.errors import must_be


def prepare_images(images: list[np.ndarray], names: list[str], crop, resize, gray: bool) -> np.ndarray:
    """(N, H, W) or (N, H, W, 3) uint8; the house error on mixed sizes without --resize or mixed channels."""
    images = [_pixels(im, name) for im, name in zip(images, names)]
    _check_same(images, names, lambda im: im.shape[:2], "image sizes (H, W)", "Pass --resize H W to bring "
                "every image to one size" + (" (after --crop)" if crop else "") + ".", resize is None)
    _check_same(images, names, lambda im: 1 if im.ndim == 2 else im.shape[2], "image channels",
                "Pass --gray to convert every image to grayscale.", not gray)
    out = [_one(im, name, crop, resize, gray) for im, name in zip(images, names)]
    h, w = out[0].shape[:2]
    lo, hi = IMAGE_SIDE_RANGE
    if not (lo <= h <= hi and lo <= w <= hi):
        raise ValueError(must_be("image size (H, W)", f"each side in [{lo}, {hi}] px", (h, w),
                                 "Pass --resize H W (and --crop to keep the part that shows the arm)."))
    return np.stack(out)


def _pixels(image: np.ndarray, name: str) -> np.ndarray:
    """The image as (H, W) or (H, W, 3) uint8, as recorded: any other dtype or channel count is refused, never
    converted (a float image in [0, 1] or a 16-bit one cast to uint8 would be all black or wrap modulo 256)."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(must_be(f"image {name}", "8-bit (uint8) pixels", str(image.dtype), "Convert the frames "
                                 "to 8 bits per channel first (a float image in [0, 1]: round(x * 255)); nothing "
                                 "is converted silently."))
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim != 2 and not (image.ndim == 3 and image.shape[2] == 3):
        raise ValueError(must_be(f"image {name}", "(H, W) gray or (H, W, 3) RGB", f"shape {image.shape}",
                                 "Keep one or three channels (drop alpha or depth channels first)."))
    return image


def _check_same(images, names, key, what: str, hint: str, enforce: bool) -> None:
    if not enforce:
        return
    first = key(images[0])
    for image, name in zip(images, names):
        if key(image) != first:
            seen = sorted({key(im) for im in images})
            raise ValueError(must_be(what, "the same for every image", f"{seen[:5]} ({name} differs from "
                                     f"{names[0]})", hint))


def _one(image: np.ndarray, name: str, crop, resize, gray: bool) -> np.ndarray:
    import cv2

    if crop is not None:
        top, left, height, width = crop
        if top + height > image.shape[0] or left + width > image.shape[1]:
            raise ValueError(must_be(f"--crop {tuple(crop)}", f"inside image {name} of (H, W) {image.shape[:2]}",
                                     (top + height, left + width), "Shrink the crop box."))
        image = image[top:top + height, left:left + width]
    if resize is not None and tuple(image.shape[:2]) != tuple(resize):
        image = cv2.resize(image, (resize[1], resize[0]), interpolation=cv2.INTER_AREA)
    if gray and image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(image)
