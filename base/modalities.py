"""The sensory modalities, one table: each one's name, unit, per-sample shape and default precision.

A modality is what a sensor reads and a SensoryModel predicts; its name is the dataset array that holds it (the
joints live in `q`). Every stage reads this table (datagen writes the store's features from it, models their
shapes and default precisions, export and the plots their units, evaluation its noise units), so a modality is
spelled once. It lives in datagen, the first stage, which every other stage may import; it imports only the
house error.

Shapes are rules over the robot: "Dq" is its number of joints, "image" the image shape (H, W[, C]).
Code branches on a row's kind ("image": a camera's frames, uint8 in the store, [0, 1] for models; "vector": the
rest), never on its name, so a second camera or a new sensor is one more row: `register(Modality(...))`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, replace

from bodyschema.errors import must_be

IMAGE_UNIT = "intensity [0, 1]"     # images are stored uint8 0–255; models and sensors see x / 255
IMAGE = "image"                     # the robot camera's modality: the default of image models and image goals
CAMERA_PREFIX = "image_"            # a robot's further camera <c> (its record's `cameras`) is the modality image_<c>
EE_PIXEL = "ee_pixel"               # the ee projected into the robot's camera; into a further camera c: ee_pixel_<c>
CAMERA_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_\-]*")   # what such a camera may be called (a store array's name)
KINDS = ("vector", "image")


@dataclass(frozen=True)
class Modality:
    name: str
    unit: str                            # of a stored sample
    shape: tuple[int | str, ...]         # per sample; "Dq" and "image" are filled in by `shape_of`
    names: tuple[str, ...]               # its components' or axes' names (a store's features, as LeRobot's)
    precision: float | None = None       # default diagonal Π = 1/σ² of an exact sensor; None: learned by the fit
    array: str = ""                      # the store array holding it: its name unless said
    dtype: str = "float32"               # as stored
    kind: str = "vector"                 # "image": a camera's frames (rendered, uint8, models see x / 255)
    camera: str | None = None            # images: the MuJoCo camera ("": the robot's own, attrs camera_name)
    sensor: bool = False                 # read by a robot sensor: a store holds it only for robots that have one
    error_unit: str = ""                 # what the benchmarks report an error in it in (deg, mm); "": its unit

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(must_be(f"modality {self.name!r} kind", f"one of {KINDS}", self.kind))
        if (self.camera is not None) != self.is_image:
            raise ValueError(must_be(f"modality {self.name!r} camera", "a camera name for an image, None otherwise",
                                     self.camera, 'Give an image row camera="" for the robot\'s own camera.'))

    @property
    def is_image(self) -> bool:
        return self.kind == "image"

    @property
    def store_array(self) -> str:
        """The store array holding it."""
        return self.array or self.name

    @property
    def reported_unit(self) -> str:
        """The unit the benchmarks report an error in it in."""
        return self.error_unit or self.unit

    @property
    def model_unit(self) -> str:
        """The unit models predict and sensors read (images in [0, 1], the rest as stored)."""
        return IMAGE_UNIT if self.is_image else self.unit


# Default precisions: 1 / σ² with σ = 1 mm, 1 px, 1° (the analytic model's fixed Π). The ee's orientation is its
# rotation matrix row by row (a hinge moves each entry by a degree-one polynomial of its cos q, sin q, as it moves
# ee_xyz: the GP's kinematic kernel holds both exactly); a turn by θ moves entries by up to θ, so σ = 1° is 0.0175.
MODALITIES: dict[str, Modality] = {m.name: m for m in (
    Modality("joints", "rad", ("Dq",), ("joint",), 1.0 / math.radians(1.0) ** 2, array="q", error_unit="deg"),
    Modality("ee_xyz", "m", (3,), ("x", "y", "z"), 1.0 / 1e-3 ** 2, error_unit="mm"),
    Modality("ee_rot", "", (9,), tuple(f"r{i}{k}" for i in range(3) for k in range(3)),
             1.0 / math.radians(1.0) ** 2),
    Modality(EE_PIXEL, "px", (2,), ("u", "v"), 1.0),
    Modality(IMAGE, "intensity", ("image",), ("row", "col", "channel"), dtype="uint8", kind="image", camera="",
             error_unit="MSE"),
    Modality("touch", "N", (1,), ("contact",), sensor=True),
    Modality("jacobian", "m/rad", (3, "Dq"), ("xyz", "joint")),
)}
KINEMATIC = ("ee_xyz", "ee_rot", EE_PIXEL, "joints")              # what forward kinematics gives (models/analytic.py)
SHIPPED = tuple(MODALITIES)


def register(row: Modality) -> Modality:
    """Add `row` to the table (a second camera, a new sensor); a name already taken is refused."""
    if row.name in MODALITIES or any(m.store_array == row.store_array for m in MODALITIES.values()):
        raise ValueError(must_be("modality name", f"new, not one of {list(MODALITIES)}", row.name,
                                 "Pick another name, or use the existing row."))
    MODALITIES[row.name] = row
    return row


def unregister(name: str) -> None:
    """Remove a row added by `register` (tests); the shipped rows stay."""
    if name in SHIPPED:
        raise ValueError(must_be("modality to remove", "one added by register", name))
    MODALITIES.pop(name, None)


def images() -> tuple[Modality, ...]:
    """The camera rows, in table order."""
    return tuple(m for m in MODALITIES.values() if m.is_image)


def camera_modality(camera: str) -> str:
    """The modality of a robot's further camera `camera`: image_<camera>, an image row like the robot's own."""
    if not isinstance(camera, str) or not CAMERA_NAME.fullmatch(camera):
        raise ValueError(must_be("camera name", f"letters, digits, _ or - ({CAMERA_NAME.pattern})", camera,
                                 "Rename the camera in the model file."))
    return f"{CAMERA_PREFIX}{camera}"


def pixel_modality(image_modality: str) -> str:
    """The ee's projection into the camera of an image modality: ee_pixel (the robot's own), ee_pixel_<c>."""
    camera = get(image_modality).camera
    return f"{EE_PIXEL}_{camera}" if camera else EE_PIXEL


def is_projection(name: str) -> bool:
    """Whether `name` is the ee projected into a camera: ee_pixel (the robot's own) or ee_pixel_<c> (a further one)."""
    return name == EE_PIXEL or _suffix(name, EE_PIXEL + "_") is not None


def find(name: str) -> Modality | None:
    """The row of `name`: the table's, a further camera's (image_<camera>, and ee_pixel_<camera> the ee projected
    into it: rows by rule, so every process knows them without registering), or None."""
    if name in MODALITIES:
        return MODALITIES[name]
    if (camera := _suffix(name, CAMERA_PREFIX)) is not None:
        return replace(MODALITIES[IMAGE], name=name, camera=camera)
    if _suffix(name, EE_PIXEL + "_") is not None:
        return replace(MODALITIES[EE_PIXEL], name=name)
    return None


def _suffix(name, prefix: str) -> str | None:
    """The camera name after `prefix` in `name`, or None when there is none."""
    camera = name[len(prefix):] if isinstance(name, str) and name.startswith(prefix) else None
    return camera if camera is not None and CAMERA_NAME.fullmatch(camera) else None


def images_in(names: Iterable[str]) -> list[str]:
    """The camera rows' store arrays among `names` (a store's array keys, an observation's): the table's in table
    order, then further cameras' in the order given."""
    names = list(names)
    table = [m.store_array for m in images() if m.store_array in names]
    return table + [n for n in names if n not in table and is_image(n)]


def is_image(name: str) -> bool:
    """Whether `name` is a camera's modality; a name outside the table is not."""
    row = find(name)
    return row is not None and row.is_image


def stored(image: bool, sensors: Iterable[str] = ()) -> tuple[Modality, ...]:
    """The rows a store holds, in its order: those every store has (computed from q), the ee's projections into
    further cameras among `sensors` (ee_pixel_<c>, computed from q too: with or without images), then, when it holds
    images, the robot's own camera and the further cameras among `sensors`, then the robot's sensor rows among
    `sensors` (what `Robot.sensors` names)."""
    rows = MODALITIES.values()
    sensors = list(dict.fromkeys(sensors))
    further = tuple(row for s in sensors if (row := find(s)) is not None and row.is_image and row.camera)
    cameras = tuple(m for m in images() if not m.camera) + further
    projections = tuple(get(s) for s in sensors if s != EE_PIXEL and is_projection(s))
    return (tuple(m for m in rows if not m.is_image and not m.sensor) + projections + (cameras if image else ())
            + tuple(m for m in rows if m.sensor and m.name in sensors))


def get(name: str) -> Modality:
    """The table's row of `name` (the joints also by their array name, "q")."""
    by_array = {m.array: m for m in MODALITIES.values() if m.array}
    if name in by_array:
        return by_array[name]
    row = find(name)
    if row is None:
        raise ValueError(f"Modality {name!r} is not known. Choose one of {list(MODALITIES)}, or "
                         f"{CAMERA_PREFIX}<camera> and {EE_PIXEL}_<camera> for a robot's further camera.")
    return row


def unit(name: str, default: str = "") -> str:
    """The unit models predict `name` in, or `default` for a name outside the table."""
    row = find(name)
    return row.model_unit if row is not None else default


def shape_of(name: str, dq: int, image_shape: tuple[int, ...] | None = None) -> tuple[int, ...]:
    """The per-sample shape of `name` for a robot with `dq` joints and images of `image_shape`."""
    rule = {"Dq": (dq,), "image": tuple(image_shape or ())}
    return tuple(d for axis in get(name).shape for d in rule.get(axis, (axis,)))


def store_feature(name: str, dq: int, image_shape: tuple[int, ...] | None = None) -> dict:
    """The store's feature entry of `name`: {dtype, shape, unit, names} (datagen/store/schema.py `features`)."""
    row = get(name)
    shape = shape_of(name, dq, image_shape)
    names = row.names[:len(shape)] if row.is_image else row.names    # a grayscale image has no channel
    return {"dtype": row.dtype, "shape": list(shape), "unit": row.unit, "names": list(names)}
