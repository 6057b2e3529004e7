"""`show_store`: what a dataset store holds, in words (`summarize_store`) and at a glance (a contact sheet PNG).

The sheet goes beside the store (`<store name>_contact_sheet.png`) unless `out` says where; a store without images
(generated with --no-images) gets the summary only, and the result says why there is no sheet. A store with images
whose robot it can rebuild (a generated one) also gets its camera's observability table (`observability.py`: pixels
changed and ee mm per degree of each joint, over the store's sampling ranges), and a house warning per joint under
the threshold.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from bodyschema.datagen.store.contact_sheet import check_png_path, write_contact_sheet
from bodyschema.datagen.store.schema import open_store
from bodyschema.datagen.store.validate import summarize_store
from bodyschema.errors import must_be

logger = logging.getLogger(__name__)

@dataclass(frozen=True)
class Shown:
    summary: str                # summarize_store's text (validity included)
    sheet: Path | None          # the contact sheet PNG, None when the store has no images
    note: str = ""              # why there is no sheet
    seen: str = ""              # the observability table ("" without images or a robot record)

    def __str__(self) -> str:
        return "\n".join([self.summary, *([self.seen] if self.seen else []),
                          f"contact sheet: {self.sheet}" if self.sheet else self.note])


def show_store(path: str | Path, out: str | Path | None = None, n: int = 16) -> Shown:
    path = Path(path)
    if out is not None:
        check_png_path(out)                 # before the summary: a bad --out fails at once
    if not path.exists():
        raise FileNotFoundError(must_be("STORE", "an existing .zarr store", str(path),
                                        "Create one with `bodyschema datagen --out PATH`."))
    summary = summarize_store(path)
    if "image" not in open_store(path).array_keys():
        return Shown(summary, None, "no contact sheet: the store has no images (it was generated with "
                                    "--no-images); summary only")
    sheet = Path(out) if out is not None else default_sheet_path(path)
    return Shown(summary, write_contact_sheet(path, sheet, n=n), seen=store_observability(path))


def store_observability(path: Path) -> str:
    """The observability table of the store's robot through each of its cameras over its sampling ranges, warnings
    logged; "" for a store that does not hold its robot (an import without --robot)."""
    import numpy as np

    from bodyschema.datagen.body.attrs import RECORD_KEY
    from bodyschema.datagen.body.observability import every_camera, unseen_warnings
    from bodyschema.datagen.body.robot import Robot

    attrs = dict(open_store(path).attrs)
    if RECORD_KEY not in attrs or not attrs.get("sampling_ranges"):
        return ""
    with Robot.from_attrs(attrs) as robot:
        seen = every_camera(robot, np.array(attrs["sampling_ranges"]))
    for warning in unseen_warnings(seen):
        logger.warning(warning)
    return "\n".join(table.table() for table in seen)


def default_sheet_path(store: Path) -> Path:
    """`data/nao.zarr` → `data/nao_contact_sheet.png`."""
    return store.parent / f"{store.name.removesuffix('.zarr')}_contact_sheet.png"
