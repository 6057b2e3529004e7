"""`RobotRecord`: what a robot's model file does not say, one TOML file per robot (issue 20, "one place per robot").

A record names the model file (MJCF .xml or URDF .urdf, relative to the record) and adds: the end effector (a site,
or a body plus an offset), the joints used (hinges; every other joint is held at `hold` or its reference pose), the
camera (one of the model's, or a pose placed to frame the ee workspace) and further cameras (`cameras`: each a
camera of the model's or a placed pose, as [camera], one more image modality image_<name> rendered at the same
size; a URDF has no cameras of its own; a placed one may ride on a link, `body`), the image size, named joint boxes
(`workspaces`, rad), the actuators (the model's own, or position servos with the gains given), the PD baseline's
gains, and the tables benchmarks read ([reaching], held as given: its keys are the reaching benchmark's to check).
The shipped robots are the records beside their MJCF (datagen/robots/<name>.toml). What each value may be:
`record_checks`.

    bodyschema datagen --robot planar2 | --robot arm.xml | --robot arm.urdf | --robot arm.toml

A model file with a record of the same stem beside it uses that record; without one, the values are inferred
(`infer.infer_record`) and `bodyschema robot init FILE` writes them for the user to edit. Pure Python
(tomllib): the CLI imports it at start-up.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from bodyschema.datagen.body import formats
from bodyschema.datagen.body.record_checks import BENCHMARK_SECTIONS, record_problems
from bodyschema.errors import must_be

RECORD_SUFFIX = ".toml"
AUTO_CAMERA = "auto"                         # the name of a camera placed by the record (not in the model file)
EE_SITE = "bodyschema_ee"                    # the site added for an ee given as a body plus an offset
SECTIONS = {"ee": ("site", "body", "offset"), "camera": ("name", "pos", "xyaxes", "fovy"),
            "actuators": ("kind", "kp", "kv"), "pd": ("kp", "kd")}
TOP_KEYS = ("name", "model", "joints", "image_size", "mesh_dir", "visual", "collisions", "hold", "workspaces",
            "cameras", *SECTIONS, *BENCHMARK_SECTIONS)

@dataclass(frozen=True)
class RobotRecord:
    """One robot: its model file and everything the pipeline needs that the file does not hold."""

    name: str                                          # what stores, models and runs call the robot
    model: str                                         # the MJCF/URDF file, relative to `base` (or absolute)
    image_size: tuple[int, int]                        # (H, W) px, the default camera image
    workspaces: dict[str, tuple[tuple[float, float], ...]]   # name → (lo, hi) rad per joint
    ee: dict[str, Any] = field(default_factory=lambda: {"site": "ee"})   # {site} | {body, offset (m)}
    joints: tuple[str, ...] = ()                       # the hinges used, in order; () = every joint of the model
    hold: dict[str, float] = field(default_factory=dict)   # other joints' held values (rad | m); else reference
    camera: dict[str, Any] = field(default_factory=dict)   # {name} of the model's | {name="auto", pos, xyaxes, fovy}
    # further cameras: a name of the model's | {name, pos, xyaxes, fovy[, body[, masked]]} placed (in the world, or
    # riding on `body`: pose in its frame; `masked`: it draws that body and those beyond alone); each one more image
    # modality
    cameras: tuple = ()
    actuators: dict[str, Any] = field(default_factory=lambda: {"kind": "model"})   # {kind, kp, kv (servos)}
    pd: dict[str, Any] = field(default_factory=dict)   # {kp, kd}: the torque PD baseline's gains per joint
    # the reaching benchmark's table, as given (its keys: control/robot_defaults.py)
    reaching: dict[str, Any] = field(default_factory=dict)
    mesh_dir: str = ""                                 # URDF: where package:// meshes are found besides the file's
    visual: str = "mesh"                               # URDF: "collision" | "primitives" (see VISUALS)
    # "none": no geom of the arm collides (as the shipped arms are built). A file's collision meshes often touch
    # each other across a joint's range, and a servo pushing into a contact jams: reaching failed for PD too.
    collisions: str = "model"
    base: Path = Path(".")                             # the folder `model` and `mesh_dir` are relative to

    def __post_init__(self):
        problems = record_problems(self)
        if problems:
            raise ValueError("\n".join(problems))

    @property
    def model_path(self) -> Path:
        return (self.base / self.model).resolve()

    @property
    def mesh_path(self) -> Path | None:
        return (self.base / self.mesh_dir).resolve() if self.mesh_dir else None

    @property
    def camera_name(self) -> str:
        return self.camera["name"]

    @property
    def further_cameras(self) -> tuple[str, ...]:
        """The names of the further cameras, in the record's order."""
        return tuple(c["name"] if isinstance(c, dict) else c for c in self.cameras)

    @property
    def placed_camera(self) -> bool:
        """True when the record places the camera itself (a pose), False for a camera of the model file."""
        return "pos" in self.camera

    def to_toml_dict(self) -> dict[str, Any]:
        """The record as TOML values (tuples as lists), `base` left out: it is where the file lies."""
        out = {"name": self.name, "model": self.model, "image_size": list(self.image_size)}
        if self.joints:
            out["joints"] = list(self.joints)
        if self.cameras:
            out["cameras"] = _plain(list(self.cameras))
        if self.mesh_dir:
            out["mesh_dir"] = self.mesh_dir
        if self.visual != "mesh":
            out["visual"] = self.visual
        if self.collisions != "model":
            out["collisions"] = self.collisions
        for key in ("ee", "camera", "hold", "actuators", "pd", *BENCHMARK_SECTIONS):
            if getattr(self, key):
                out[key] = _plain(getattr(self, key))
        out["workspaces"] = _plain(self.workspaces)
        return out


# ---- reading ----------------------------------------------------------------------------------------------
def shipped_dir() -> Path:
    return Path(str(resources.files("bodyschema.datagen").joinpath("robots")))


def _shipped_names() -> tuple[str, ...]:
    """The robots whose records ship as datagen/robots/<name>.toml, fewest joints (rows of the `full` workspace)
    first, then by name: the 2-joint toy arm leads every list shown to a user."""
    robots = resources.files("bodyschema.datagen").joinpath("robots")
    joints = {Path(f.name).stem: len(tomllib.loads(f.read_text())["workspaces"]["full"])
              for f in robots.iterdir() if f.name.endswith(RECORD_SUFFIX)}
    return tuple(sorted(joints, key=lambda name: (joints[name], name)))


SHIPPED = _shipped_names()


def is_robot_file(ref: str) -> bool:
    """True when `ref` names a file (a model or record suffix), False for a shipped robot's name."""
    return Path(str(ref)).suffix.lower() in (*formats.suffixes(), RECORD_SUFFIX)


def check_robot_ref(ref: object) -> str | None:
    """The house problem with a robot reference (a shipped name or an existing .xml/.urdf/.toml file), or None."""
    expected = f"one of {SHIPPED} or a path to an {formats.described()} file or a robot record (.toml)"
    if not isinstance(ref, (str, Path)) or not str(ref):
        return must_be("robot", expected, ref)
    if str(ref) in SHIPPED:
        return None
    if not is_robot_file(str(ref)):
        return must_be("robot", expected, str(ref), "Other model formats: convert them to one of these first.")
    if not Path(ref).is_file():
        return must_be("robot", f"{expected} that exists", str(ref), "Check the path (relative to the cwd).")
    return None


def robot_label(ref: str) -> str:
    """A short name for file names: the shipped name, or the file's stem."""
    return str(ref) if str(ref) in SHIPPED else Path(str(ref)).stem


def load_record(ref: str | Path) -> RobotRecord | None:
    """The record of a robot reference: a shipped name, a .toml, or a model file's sibling <stem>.toml.
    None for a model file without a record (its values are inferred by `infer.infer_record`)."""
    problem = check_robot_ref(ref)
    if problem:
        raise ValueError(problem)
    path = shipped_dir() / f"{ref}.toml" if str(ref) in SHIPPED else Path(ref)
    if path.suffix.lower() in formats.suffixes():
        sibling = path.with_suffix(RECORD_SUFFIX)
        if not sibling.is_file():
            return None
        record = read_record(sibling)
        if record.model_path != path.resolve():
            raise ValueError(must_be(f"the record {sibling}", f"about {path.name}", record.model,
                                     "Fix its `model` key or move the record."))
        return record
    return read_record(path)


def read_record(path: Path) -> RobotRecord:
    """Parse and check one record file; the house error names the file and the key."""
    try:
        values = tomllib.loads(Path(path).read_text())
    except tomllib.TOMLDecodeError as e:
        raise ValueError(must_be(f"robot record {path}", "valid TOML", str(e))) from e
    base = Path(path).resolve().parent
    name = values.get("name")
    if isinstance(name, str) and name in SHIPPED and base != shipped_dir().resolve():
        # a store names its robot, and a shipped name is checked against the shipped model: refuse it here, not at
        # `validate` after the whole datagen run
        raise ValueError(must_be(f"record `name` in {path}", f"not a shipped robot's name {SHIPPED}", name,
                                 f"Stores and models are checked against the shipped {name}; rename it, e.g. "
                                 f"{name}_{Path(path).stem}."))
    return record_from_dict(values, base, str(path))


def record_from_dict(values: dict[str, Any], base: Path, where: str = "robot record") -> RobotRecord:
    """A record from its TOML values (as `to_toml_dict` writes them), relative paths against `base`."""
    unknown = sorted(set(values) - set(TOP_KEYS))
    if unknown:
        raise ValueError(must_be(f"the keys of {where}", f"among {list(TOP_KEYS)}", unknown))
    for section, keys in SECTIONS.items():
        extra = sorted(set(values.get(section, {}) or {}) - set(keys)) if isinstance(values.get(section), dict) else []
        if extra:
            raise ValueError(must_be(f"[{section}] of {where}", f"keys among {list(keys)}", extra))
    for key in ("name", "model", "image_size", "workspaces"):
        if key not in values:
            raise ValueError(must_be(where, f"a record with a `{key}` key", sorted(values)))
    for key in ("hold", "workspaces", *SECTIONS, *BENCHMARK_SECTIONS):
        if key in values and not isinstance(values[key], dict):
            raise ValueError(must_be(f"`{key}` of {where}", f"a table ([{key}] with its keys)", values[key]))
    kwargs = dict(values)
    kwargs["image_size"] = tuple(values["image_size"]) if isinstance(values["image_size"], list) else None
    joints = values.get("joints", [])
    kwargs["joints"] = tuple(joints) if isinstance(joints, list) else joints    # a string is refused, not split
    cameras = values.get("cameras", [])
    kwargs["cameras"] = tuple(cameras) if isinstance(cameras, list) else cameras
    kwargs["workspaces"] = {k: _tuples(v) for k, v in values["workspaces"].items()}
    return RobotRecord(**kwargs, base=base)


def _tuples(box: Any) -> Any:
    """[[lo, hi], ...] as tuples; anything else as it came (the checks name it)."""
    return tuple(tuple(r) if isinstance(r, list) else r for r in box) if isinstance(box, list) else box


# ---- writing ----------------------------------------------------------------------------------------------
def write_record(record: RobotRecord, path: Path, header: str = "") -> Path:
    """Write `record` as TOML at `path` (atomically: a temporary sibling, then a rename)."""
    text = "".join(f"# {line}\n" for line in header.splitlines()) + dumps_toml(record.to_toml_dict())
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def dumps_toml(values: dict[str, Any], prefix: str = "") -> str:
    """TOML for nested dicts of str, int, float, bool and lists: scalars first, then one [table] per dict.
    Floats are written with repr, which reads back to the same float."""
    lines = [f"{_key(k)} = {_value(v)}" for k, v in values.items() if not isinstance(v, dict)]
    tables = [(k, v) for k, v in values.items() if isinstance(v, dict)]
    text = "\n".join(lines) + ("\n" if lines else "")
    for key, table in tables:
        name = f"{prefix}{_key(key)}"
        text += f"\n[{name}]\n" + dumps_toml(table, name + ".")
    return text


def _key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() else f'"{key}"'


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v) if not isinstance(v, float) or math.isfinite(v) else ("nan" if v != v else
                                                                              ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):                               # an inline table: a list's entry (a placed camera)
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no TOML value for {type(v).__name__}")


def _plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return float(v) if hasattr(v, "dtype") else v
