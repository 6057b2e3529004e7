"""`ImportConfig`: what `bodyschema import` reads, how it reads it, and where the store goes (checked on entry).

Light on purpose (the CLI builds it at start-up): no numpy, MuJoCo or h5py here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from bodyschema.cli_marks import Positional
from bodyschema.errors import must_be

FORMATS = ("auto", "folder", "hdf5", "lerobot")
IMAGE_SIDE_RANGE = (8, 1024)  # px, as datagen: below 8 nothing is visible, above 1024 one sample is > 3 MB


@dataclass(frozen=True)
class ImportConfig:
    """Import recorded joint angles (and camera frames, ee readings) into a dataset store that `bodyschema validate`,
    `train` and `evaluate levels --targets` take like a generated one.

    SOURCE: a folder of images plus a CSV of joint angles (one row per image), an HDF5 file (this project's export,
    or per episode `<episode>/obs/<joint key>` + `<episode>/obs/<image key>`) or a LeRobot v3.0 dataset folder."""

    source: Annotated[Path, Positional("SOURCE")]
    """a folder of images + a CSV of angles, an .h5/.hdf5 file, or a LeRobot v3.0 dataset folder"""
    out: Path                              # the .zarr store to write (built beside it, then renamed into place)
    format: Literal["auto", "folder", "hdf5", "lerobot"] = "auto"   # auto: .h5 file, meta/info.json, else folder
    angles: Literal["deg", "rad"] | None = None   # unit of the angles and --ranges; required unless the source says
    robot: str | None = None               # the body: a shipped robot (joints, limits, camera, --fk); or --joints
    joints: tuple[str, ...] | None = None  # the body without a robot: joint names in q's order (limits: --ranges)
    ranges: tuple[tuple[float, float], ...] | None = None   # (lo, hi) per joint, --angles unit; None: the data's box
    name: str = "recorded"                 # the body's name with --joints (models trained on the store carry it)
    csv: Path | None = None                # folder: the CSV of angles; None: the one *.csv in SOURCE
    joint_key: tuple[str, ...] = ()        # hdf5 demo: obs key(s) of the angles; lerobot: default observation.state
    image_key: str | None = None           # hdf5 demo / lerobot: the image key; None: the only image there is
    ee_key: str | None = None              # hdf5 demo: obs key of the ee position (m), imported as ee_xyz
    images: bool = True                    # --no-images: joint angles (and ee readings) only
    crop: tuple[int, int, int, int] | None = None   # (top, left, height, width) px, applied before --resize
    resize: tuple[int, int] | None = None  # (H, W) px for every image; required when the sizes differ
    gray: bool = False                     # convert colour frames to grayscale (ITU-R BT.601, as datagen renders)
    fk: bool = False                       # ee_xyz, ee_pixel, jacobian from --robot's kinematics (replace recorded)
    overwrite: bool = False                # replace OUT if it exists

    def __post_init__(self) -> None:
        problems = []
        if self.format not in FORMATS:
            problems.append(must_be("--format", f"one of {FORMATS}", self.format))
        if self.angles not in (None, "deg", "rad"):
            problems.append(must_be("--angles", "deg or rad", self.angles))
        if self.robot is not None and self.joints is not None:
            problems.append(must_be("the body", "--robot NAME or --joints NAMES, not both",
                                    f"robot={self.robot}, joints={self.joints}",
                                    "A robot gives joints, limits and camera; --joints gives names (limits: "
                                    "--ranges, else the data's box)."))
        if self.joints is not None:
            if not self.joints or len(set(self.joints)) != len(self.joints):
                problems.append(must_be("--joints", "distinct joint names", self.joints))
        if self.ranges is not None and not all(len(r) == 2 and all(math.isfinite(v) for v in r) and r[0] < r[1]
                                               for r in self.ranges):
            problems.append(must_be("--ranges", "finite (lo, hi) pairs with lo < hi", self.ranges))
        if self.fk and self.robot is None:
            problems.append(must_be("--fk", "used with --robot", "--joints", "Forward kinematics need a robot."))
        lo, hi = IMAGE_SIDE_RANGE
        if self.resize is not None and not all(lo <= s <= hi for s in self.resize):
            problems.append(must_be("--resize", f"(H, W) with each side in [{lo}, {hi}] px", self.resize))
        if self.crop is not None and (min(self.crop[:2]) < 0 or min(self.crop[2:]) < 1):
            problems.append(must_be("--crop", "(top, left, height, width) px with top, left >= 0 and sizes >= 1",
                                    self.crop))
        if problems:
            raise ValueError("\n".join(problems))

    @property
    def to_rad(self) -> float:
        """Factor from the recorded unit to rad (1 when the source states rad and no --angles came)."""
        return math.pi / 180.0 if self.angles == "deg" else 1.0

    def to_dict(self) -> dict:
        """The config as JSON values, as stored in the store's attrs."""
        import dataclasses
        import json
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))
