"""Contact-sheet labels are readable on any image (white text on a dark box, also over a white hand) and never sit on
the ee_pixel marker; the sheet keeps one tile per sample."""

import cv2
import numpy as np
import pytest
import zarr

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.contact_sheet import LABEL_BOX, draw_label, label_corner, write_contact_sheet


@pytest.mark.parametrize(("marker", "corner"), [((10, 10), (True, True)), ((150, 10), (False, True)),
                                                ((10, 150), (True, False)), ((150, 150), (False, False)),
                                                (None, (False, False))])
def test_the_label_goes_to_the_corner_farthest_from_the_marker(marker, corner):
    assert label_corner(marker, 160, 160) == corner


@pytest.mark.parametrize("background", [0, 255])
def test_a_label_is_white_on_a_dark_box_over_black_and_over_white(background):
    tile = np.full((120, 160, 3), background, np.uint8)
    x0, y0, x1, y1 = draw_label(tile, "#123", (True, True))
    box = tile[y0:y1 + 1, x0:x1 + 1].max(axis=-1)                    # (h, w) brightest channel
    dark, bright = box <= max(LABEL_BOX), box >= 200
    assert dark.mean() > 0.5 and bright.sum() > 20, "mostly box, with white strokes of text on it"
    assert (x1, y1) == (158, 118), "bottom right, inside the tile's 1 px frame"
    outside = np.ones(tile.shape[:2], bool)
    outside[y0:y1 + 1, x0:x1 + 1] = False
    assert (tile[outside] == background).all(), "nothing drawn outside the box"


def test_no_label_covers_a_stored_marker(tmp_path):
    store = generate(DatagenConfig(robot="planar2", n=8, shard_size=8, seed=5, out=tmp_path / "s.zarr"),
                     progress=False)
    sheet = cv2.imread(str(write_contact_sheet(store, tmp_path / "sheet.png", n=4)))
    root = zarr.open_group(str(store), mode="r")
    h, w = root["image"].shape[1:3]
    scale = sheet.shape[1] // (2 * w)                                   # a 2 x 2 grid of upscaled tiles
    rows = np.unique(np.linspace(0, 7, 4).round().astype(int))
    for k, (u, v) in enumerate(root["ee_pixel"].get_orthogonal_selection((rows,))):
        tile = sheet[(k // 2) * h * scale:(k // 2 + 1) * h * scale, (k % 2) * w * scale:(k % 2 + 1) * w * scale]
        x, y = int(round((u + 0.5) * scale - 0.5)), int(round((v + 0.5) * scale - 0.5))
        x0, y0, x1, y1 = draw_label(np.zeros_like(tile), f"#{rows[k]}", label_corner((x, y), *tile.shape[1::-1]))
        assert not (x0 <= x <= x1 and y0 <= y <= y1), f"tile {k}: the label would hide the marker"
        box = tile[y0:y1 + 1, x0:x1 + 1].astype(int)
        assert (np.abs(box - LABEL_BOX).max(axis=-1) == 0).mean() > 0.5, f"tile {k}: its label box is drawn there"
        red = (box[..., 2] > 200) & (box[..., 1] < 80)
        assert not red.any(), f"tile {k}: no marker stroke under the label"
