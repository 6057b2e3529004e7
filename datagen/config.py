"""`DatagenConfig`: everything that defines a motor-babbling dataset, validated where it enters.

The fields that change the data (robot, n, sampler, seed, ranges, ...) form the dataset's identity
(`identity()`), stored in the Zarr attrs and compared on resume; the fields that only change *how* the data is
made (workers, backend, out, overwrite) are left out, so 1 or 8 workers, loky or ray, give the same store.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from bodyschema.datagen.body.record import check_robot_ref, robot_label
from bodyschema.datagen.body.record_checks import REQUIRED_WORKSPACES
from bodyschema.errors import must_be
from bodyschema.log import Progress

SAMPLERS = ("uniform", "gaussian", "babble")
BACKENDS = ("loky", "ray")
KINEMATIC_SAMPLERS = ("uniform", "gaussian")
WORKSPACES = REQUIRED_WORKSPACES  # the joint boxes every robot record names
IMAGE_SIDE_RANGE = (8, 1024)  # px; below 8 nothing is visible, above 1024 one sample is > 3 MB
EXECUTION_FIELDS = ("workers", "backend", "out", "overwrite", "progress")  # how, not what: excluded from identity()
MAX_GRAVITY = 100.0  # m/s^2, ~10 g (Jupiter: 24.8); far beyond, the babbling simulation diverges (1e30: NaN-like)
WORKERS_PER_CPU = 4  # more processes than this per core only add start-up and memory, never speed
BABBLE_FLAGS = ("hold_s", "record_hz", "episode_s")  # shape babbling only: set with another sampler, a mistake


@dataclass(frozen=True)
class DatagenConfig:
    """One dataset: which robot, how many samples, how they are drawn, and where they go."""

    robot: str = "planar2"  # planar2 | nao_arm | panda, or an MJCF/URDF/record path; planar2 (2-DoF): seconds
    n: int = 10_000  # samples; 10k fits a GPR on ee_xyz and an MDN on pixels within minutes
    sampler: Literal["uniform", "gaussian", "babble"] = "uniform"  # how q is drawn; uniform covers the box evenly
    image_size: tuple[int, int] | None = None  # (H, W) px; None: the robot's camera default (nao_arm 56 x 80)
    rgb: bool = False  # colour images; grayscale by default, what the seed paper's pixel decoder learns from
    images: bool = True  # render camera images; --no-images: kinematics only, ~100x faster
    workers: int = 1  # parallel processes; 1 by default, the data do not depend on it
    backend: Literal["loky", "ray"] = "loky"  # loky: local cores, no server; ray: a cluster (RAY_ADDRESS)
    seed: int = 0  # shard i draws from SeedSequence([seed, i]); same seed -> byte-identical arrays
    out: Path | None = None  # the .zarr store to write; None: data/<robot>_<sampler>_<n>.zarr
    overwrite: bool = False  # replace an existing store made with another config (refused otherwise)
    workspace: Literal["full", "camera"] | None = None  # robot joint box to sample; None: camera if images else full
    # ("camera": the poses the camera sees, so the arm is in view; "full": the whole kinematic box)
    ranges: tuple[tuple[float, float], ...] | None = None  # (lo, hi) rad per joint, overrides workspace; None: its box
    gravity: float | None = None  # m/s^2 magnitude, pointing down; None: 9.81 (0 or 3.7 for adaptation studies)
    shard_size: int | None = None  # samples per shard = Zarr chunk rows; None: 512 with images, 16384 without
    # (~1-3 MB chunks: small enough for progress and resume, large enough that Zarr calls cost nothing)
    hold_s: tuple[float, float] = (0.2, 1.0)  # babble: each random target is held U(min, max) s, a human-like pace
    record_hz: float = 20.0  # babble: recording rate (Hz), ~ a camera frame rate
    episode_s: float = 10.0  # babble: episode length (s); each starts at rest from a random pose
    progress: Progress = False  # show a bar over the shards (--quiet hides it too), as every other command

    def __post_init__(self) -> None:
        def fix(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        problems: list[str] = []
        if check_robot_ref(self.robot):
            problems.append(check_robot_ref(self.robot))
        if self.sampler not in SAMPLERS:
            problems.append(must_be("sampler", f"one of {SAMPLERS}", self.sampler))
        if self.backend not in BACKENDS:
            problems.append(must_be("backend", f"one of {BACKENDS}", self.backend))
        for name, low in (("n", 1), ("workers", 1), ("shard_size", 1), ("seed", 0)):
            value = getattr(self, name)
            if name == "shard_size" and value is None:
                continue
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                problems.append(must_be(name, f"an integer >= {low}", value))
        if isinstance(self.workers, int) and self.workers > max_workers():
            problems.append(must_be("workers", f"<= {max_workers()} ({WORKERS_PER_CPU} x {os.cpu_count()} CPUs)",
                                    self.workers, "Each worker is a process; more than the cores only wait."))
        if self.image_size is not None:
            lo, hi = IMAGE_SIDE_RANGE
            size = self.image_size
            if (not isinstance(size, (tuple, list)) or len(size) != 2
                    or not all(isinstance(s, int) and not isinstance(s, bool) and lo <= s <= hi for s in size)):
                problems.append(must_be("image_size", f"(H, W) with integers in [{lo}, {hi}] px, or None", size))
            else:
                fix("image_size", tuple(size))
        if self.workspace is not None and self.workspace not in WORKSPACES:
            problems.append(must_be("workspace", f"one of {WORKSPACES} or None", self.workspace,
                                    "None picks camera with images, full with --no-images."))
        if self.ranges is not None:
            try:
                ranges = tuple((float(a), float(b)) for a, b in self.ranges)
            except (TypeError, ValueError):
                ranges = None
            if not ranges or not all(math.isfinite(a) and math.isfinite(b) and a < b for a, b in ranges):
                problems.append(must_be("ranges", "a non-empty sequence of finite (lo, hi) rad with lo < hi, or None",
                                        self.ranges))
            else:
                fix("ranges", ranges)
        if self.gravity is not None:
            if (not isinstance(self.gravity, (int, float)) or isinstance(self.gravity, bool)
                    or not 0 <= self.gravity <= MAX_GRAVITY):
                problems.append(must_be("gravity", f"a magnitude in [0, {MAX_GRAVITY:g}] m/s^2 (down), or None",
                                        self.gravity, "Earth is 9.81, Mars 3.7, Jupiter 24.8."))
            else:
                fix("gravity", float(self.gravity))
        try:
            hold = tuple(float(h) for h in self.hold_s)
        except (TypeError, ValueError):
            hold = ()
        if len(hold) != 2 or not 0 < hold[0] <= hold[1] < math.inf:
            problems.append(must_be("hold_s", "(min, max) seconds with 0 < min <= max", self.hold_s))
        else:
            fix("hold_s", hold)
        if not (isinstance(self.record_hz, (int, float)) and 0 < self.record_hz < math.inf):
            problems.append(must_be("record_hz", "a finite positive rate in Hz", self.record_hz))
        elif not (isinstance(self.episode_s, (int, float)) and math.isfinite(self.episode_s * self.record_hz)):
            problems.append(must_be("episode_s", "a finite duration in s", self.episode_s,
                                    "An episode longer than --n is cut to --n samples anyway."))
        elif self.episode_s * self.record_hz < 2:
            problems.append(must_be("episode_s", f"long enough for >= 2 samples at record_hz={self.record_hz}",
                                    self.episode_s, "Raise --episode-s or --record-hz."))
        problems += self._conflicts()
        if self.out is not None:
            fix("out", Path(self.out))
        if problems:
            raise ValueError("\n".join(problems))

    def _conflicts(self) -> list[str]:
        """Flags the user set that this config would silently ignore (compared with the defaults)."""
        problems = []
        if not self.images:
            ignored = {_flag(name): getattr(self, name) for name, default in (("rgb", False), ("image_size", None))
                       if getattr(self, name) != default}
            if ignored:
                problems.append(must_be("image flags with --no-images", "unset (nothing is rendered)", ignored,
                                        "Drop them, or drop --no-images."))
        if self.kinematic:
            defaults = {f.name: f.default for f in dataclasses.fields(self) if f.name in BABBLE_FLAGS}
            ignored = {_flag(name): getattr(self, name) for name, default in defaults.items()
                       if getattr(self, name) != default}
            if ignored:
                problems.append(must_be(f"babbling flags with --sampler {self.sampler}",
                                        "unset (they shape babbling only)", ignored,
                                        "Drop them, or pass --sampler babble."))
        return problems

    @property
    def store_path(self) -> Path:
        """Where the store goes: `out`, or data/<robot>_<sampler>_<n>.zarr."""
        name = f"{robot_label(self.robot)}_{self.sampler}_{self.n}.zarr"
        return self.out if self.out is not None else Path("data") / name

    @property
    def workspace_name(self) -> str:
        """The robot workspace sampled from: `workspace`, or "camera" with images and "full" without."""
        if self.workspace is not None:
            return self.workspace
        return "camera" if self.images else "full"

    @property
    def kinematic(self) -> bool:
        """True when samples are independent poses (uniform, gaussian); False for babbling trajectories."""
        return self.sampler in KINEMATIC_SAMPLERS

    def shard_rows(self) -> int:
        """The requested samples per shard (`shard_size`, or its default for images / kinematics only)."""
        if self.shard_size is not None:
            return self.shard_size
        return 512 if self.images else 16384

    def episode_len(self) -> int:
        """Samples per babbling episode (fixed, so episodes and shards line up); at most n, all a store holds."""
        return min(self.n, max(2, round(self.episode_s * self.record_hz)))

    def to_dict(self) -> dict[str, Any]:
        """The config as plain JSON values (tuples as lists, Path as str), as stored in the Zarr attrs."""
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))

    def identity(self) -> dict[str, Any]:
        """The fields that determine the data; two configs with equal identity write byte-identical arrays."""
        return {k: v for k, v in self.to_dict().items() if k not in EXECUTION_FIELDS}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> DatagenConfig:
        """Rebuild a config from `to_dict()` output (lists back to tuples); unknown keys are an error."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise ValueError(must_be("config keys", f"a subset of {sorted(names)}", unknown))

        def tup(v: Any) -> Any:
            return tuple(tup(x) for x in v) if isinstance(v, list) else v

        return cls(**{k: tup(v) for k, v in values.items()})


def _flag(field: str) -> str:
    return "--" + field.replace("_", "-")


def max_workers() -> int:
    """The most worker processes a run may start: WORKERS_PER_CPU per CPU of this machine."""
    return WORKERS_PER_CPU * (os.cpu_count() or 1)
