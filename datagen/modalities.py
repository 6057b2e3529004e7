"""The sensory modalities, one table: each one's name, unit, per-sample shape and default precision.

A modality is what a sensor reads and a SensoryModel predicts; its name is the dataset array that holds it (the
joints live in `q`). Every stage reads this table (datagen writes the store's features from it, models their
shapes and default precisions, export and the plots their units, evaluation its noise units), so a modality is
spelled once. It lives in datagen, the first stage, which every other stage may import; it imports nothing.

Shapes are rules over the robot: "Dq" is its number of joints, "image" the image shape (H, W[, C]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

IMAGE_UNIT = "intensity [0, 1]"     # images are stored uint8 0–255; models and sensors see x / 255


@dataclass(frozen=True)
class Modality:
    name: str
    unit: str                            # of a stored sample
    shape: tuple[int | str, ...]         # per sample; "Dq" and "image" are filled in by `shape_of`
    names: tuple[str, ...]               # its components' or axes' names (a store's features, as LeRobot's)
    precision: float | None = None       # default diagonal Π = 1/σ² of an exact sensor; None: learned by the fit
    array: str = ""                      # the store array holding it: its name unless said
    dtype: str = "float32"               # as stored

    @property
    def model_unit(self) -> str:
        """The unit models predict and sensors read (images in [0, 1], the rest as stored)."""
        return IMAGE_UNIT if self.name == "image" else self.unit


# Default precisions: 1 / σ² with σ = 1 mm, 1 px, 1° (the analytic model's fixed Π).
MODALITIES: dict[str, Modality] = {m.name: m for m in (
    Modality("joints", "rad", ("Dq",), ("joint",), 1.0 / math.radians(1.0) ** 2, array="q"),
    Modality("ee_xyz", "m", (3,), ("x", "y", "z"), 1.0 / 1e-3 ** 2),
    Modality("ee_pixel", "px", (2,), ("u", "v"), 1.0),
    Modality("image", "intensity", ("image",), ("row", "col", "channel"), dtype="uint8"),
    Modality("touch", "N", (1,), ("contact",)),
    Modality("jacobian", "m/rad", (3, "Dq"), ("xyz", "joint")),
)}
KINEMATIC = ("ee_xyz", "ee_pixel", "joints")            # what forward kinematics gives (models/analytic.py)


def get(name: str) -> Modality:
    """The table's row of `name` (the joints also by their array name, "q")."""
    by_array = {m.array: m for m in MODALITIES.values() if m.array}
    if name in by_array:
        return by_array[name]
    if name not in MODALITIES:
        raise ValueError(f"Modality {name!r} is not known. Choose one of {list(MODALITIES)}.")
    return MODALITIES[name]


def unit(name: str, default: str = "") -> str:
    """The unit models predict `name` in, or `default` for a name outside the table."""
    return MODALITIES[name].model_unit if name in MODALITIES else default


def shape_of(name: str, dq: int, image_shape: tuple[int, ...] | None = None) -> tuple[int, ...]:
    """The per-sample shape of `name` for a robot with `dq` joints and images of `image_shape`."""
    rule = {"Dq": (dq,), "image": tuple(image_shape or ())}
    return tuple(d for axis in get(name).shape for d in rule.get(axis, (axis,)))


def store_feature(name: str, dq: int, image_shape: tuple[int, ...] | None = None) -> dict:
    """The store's feature entry of `name`: {dtype, shape, unit, names} (datagen/store.py `features`)."""
    row = get(name)
    shape = shape_of(name, dq, image_shape)
    names = row.names[:len(shape)] if "image" in row.shape else row.names    # a grayscale image has no channel
    return {"dtype": row.dtype, "shape": list(shape), "unit": row.unit, "names": list(names)}
