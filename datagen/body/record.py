"""`RobotRecord`: what a robot's model file does not say, one TOML file per robot (issue 20, "one place per robot").

A record names the model file (MJCF .xml or URDF .urdf, relative to the record) and adds: the end effector (a site,
or a body plus an offset), the joints used (hinges; every other joint is held at `hold` or its reference pose), the
camera (one of the model's, or a pose placed to frame the ee workspace), the image size, named joint boxes
(`workspaces`, rad), the actuators (the model's own, or position servos with the gains given), the PD baseline's
gains and the reaching defaults. The shipped robots are records beside their MJCF (datagen/robots/<name>.toml).

    bodyschema datagen --robot planar2 | --robot arm.xml | --robot arm.urdf | --robot arm.toml

A model file with a record of the same stem beside it uses that record; without one, the values are inferred
(`robot_infer.infer_record`) and `bodyschema robot init FILE` writes them for the user to edit. Pure Python
(tomllib): the CLI imports it at start-up.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from bodyschema.errors import must_be

SHIPPED = ("planar2", "nao_arm", "panda")    # datagen/robots/<name>.toml beside <name>.xml
MODEL_SUFFIXES = (".xml", ".urdf")
RECORD_SUFFIX = ".toml"
AUTO_CAMERA = "auto"                         # the name of a camera placed by the record (not in the model file)
EE_SITE = "bodyschema_ee"                    # the site added for an ee given as a body plus an offset
ACTUATORS = ("model", "servos")              # the model's own actuators | position servos added with [actuators] gains
VISUALS = ("mesh", "collision", "primitives")   # URDF: render the visual meshes | the collision geometry instead |
                                                # capsules and boxes from the links (no mesh read; datagen/primitives)
COLLISIONS = ("model", "none")               # contacts as the file has them | the arm's geoms collide with nothing
REQUIRED_WORKSPACES = ("full", "camera")     # every record names these two (datagen picks one by --images)
SECTIONS = {"ee": ("site", "body", "offset"), "camera": ("name", "pos", "xyaxes", "fovy"),
            "actuators": ("kind", "kp", "kv"), "pd": ("kp", "kd"),
            "reaching": ("models", "control_hz", "duration_s", "actuators", "action")}
NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")   # a file name everywhere: stores, models, runs
TOP_KEYS = ("name", "model", "joints", "image_size", "mesh_dir", "visual", "collisions", "hold", "workspaces",
            *SECTIONS)


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
    actuators: dict[str, Any] = field(default_factory=lambda: {"kind": "model"})   # {kind, kp, kv (servos)}
    pd: dict[str, Any] = field(default_factory=dict)   # {kp, kd}: the torque PD baseline's gains per joint
    reaching: dict[str, Any] = field(default_factory=dict)   # models, control_hz, duration_s, actuators, action
    mesh_dir: str = ""                                 # URDF: where package:// meshes are found besides the file's
    visual: str = "mesh"                               # URDF: "collision" | "primitives" (see VISUALS)
    # "none": no geom of the arm collides (as the shipped arms are built). A file's collision meshes often touch
    # each other across a joint's range, and a servo pushing into a contact jams: reaching failed for PD too.
    collisions: str = "model"
    base: Path = Path(".")                             # the folder `model` and `mesh_dir` are relative to

    def __post_init__(self):
        problems = _problems(self)
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
    def placed_camera(self) -> bool:
        """True when the record places the camera itself (a pose), False for a camera of the model file."""
        return "pos" in self.camera

    def to_toml_dict(self) -> dict[str, Any]:
        """The record as TOML values (tuples as lists), `base` left out: it is where the file lies."""
        out = {"name": self.name, "model": self.model, "image_size": list(self.image_size)}
        if self.joints:
            out["joints"] = list(self.joints)
        if self.mesh_dir:
            out["mesh_dir"] = self.mesh_dir
        if self.visual != "mesh":
            out["visual"] = self.visual
        if self.collisions != "model":
            out["collisions"] = self.collisions
        for key in ("ee", "camera", "hold", "actuators", "pd", "reaching"):
            if getattr(self, key):
                out[key] = _plain(getattr(self, key))
        out["workspaces"] = _plain(self.workspaces)
        return out


# ---- reading ----------------------------------------------------------------------------------------------
def shipped_dir() -> Path:
    return Path(str(resources.files("bodyschema.datagen").joinpath("robots")))


def is_robot_file(ref: str) -> bool:
    """True when `ref` names a file (a model or record suffix), False for a shipped robot's name."""
    return Path(str(ref)).suffix.lower() in (*MODEL_SUFFIXES, RECORD_SUFFIX)


def check_robot_ref(ref: object) -> str | None:
    """The house problem with a robot reference (a shipped name or an existing .xml/.urdf/.toml file), or None."""
    expected = f"one of {SHIPPED} or a path to an MJCF (.xml), URDF (.urdf) or robot record (.toml)"
    if not isinstance(ref, (str, Path)) or not str(ref):
        return must_be("robot", expected, ref)
    if str(ref) in SHIPPED:
        return None
    if not is_robot_file(str(ref)):
        return must_be("robot", expected, str(ref), "Other model formats: convert them to MJCF or URDF first.")
    if not Path(ref).is_file():
        return must_be("robot", f"{expected} that exists", str(ref), "Check the path (relative to the cwd).")
    return None


def robot_label(ref: str) -> str:
    """A short name for file names: the shipped name, or the file's stem."""
    return str(ref) if str(ref) in SHIPPED else Path(str(ref)).stem


def load_record(ref: str | Path) -> RobotRecord | None:
    """The record of a robot reference: a shipped name, a .toml, or a model file's sibling <stem>.toml.
    None for a model file without a record (its values are inferred by `robot_infer.infer_record`)."""
    problem = check_robot_ref(ref)
    if problem:
        raise ValueError(problem)
    path = shipped_dir() / f"{ref}.toml" if str(ref) in SHIPPED else Path(ref)
    if path.suffix.lower() in MODEL_SUFFIXES:
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
    for key in ("hold", "workspaces", *SECTIONS):
        if key in values and not isinstance(values[key], dict):
            raise ValueError(must_be(f"`{key}` of {where}", f"a table ([{key}] with its keys)", values[key]))
    kwargs = dict(values)
    kwargs["image_size"] = tuple(values["image_size"]) if isinstance(values["image_size"], list) else None
    joints = values.get("joints", [])
    kwargs["joints"] = tuple(joints) if isinstance(joints, list) else joints    # a string is refused, not split
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
    raise TypeError(f"no TOML value for {type(v).__name__}")


def _plain(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return float(v) if hasattr(v, "dtype") else v


# ---- checks -----------------------------------------------------------------------------------------------
def _problems(r: RobotRecord) -> list[str]:
    p = []
    if not (isinstance(r.name, str) and NAME_PATTERN.fullmatch(r.name)):
        p.append(must_be("record `name`", "1-64 letters, digits, '_', '-' or '.', not starting with '.' or '-'",
                         r.name, "It names stores, models and runs: e.g. my_arm."))
    for key in ("ee", "hold", "camera", "actuators", "pd", "reaching", "workspaces"):
        if not isinstance(getattr(r, key), dict):
            return [*p, must_be(f"record `{key}`", f"a table ([{key}] with its keys)", getattr(r, key))]
    if not isinstance(r.mesh_dir, str):
        p.append(must_be("record `mesh_dir`", "a folder path (text), relative to the record", r.mesh_dir))
    if not (isinstance(r.model, str) and Path(r.model).suffix.lower() in MODEL_SUFFIXES):
        p.append(must_be("record `model`", "a path to an MJCF (.xml) or URDF (.urdf) file", r.model,
                         "Other formats: convert them to MJCF or URDF first."))
    size = r.image_size
    if not (isinstance(size, tuple) and len(size) == 2 and all(isinstance(s, int) and 8 <= s <= 1024 for s in size)):
        p.append(must_be("record `image_size`", "[H, W] with integers in [8, 1024] px", size))
    p += _ee_problems(r.ee)
    if not isinstance(r.joints, tuple) or not all(isinstance(j, str) and j for j in r.joints) or \
            len(set(r.joints)) != len(r.joints):
        p.append(must_be("record `joints`", "a list of distinct joint names, e.g. [\"shoulder\", \"elbow\"]",
                         r.joints))
    if not (all(isinstance(k, str) for k in r.hold) and _finite(r.hold.values())):
        p.append(must_be("record [hold]", "joint = finite value (rad or m)", r.hold))
    p += _camera_problems(r.camera)
    p += _workspace_problems(r.workspaces)
    if r.actuators.get("kind") not in ACTUATORS:
        p.append(must_be("record [actuators] kind", f"one of {ACTUATORS}", r.actuators.get("kind")))
    elif r.actuators["kind"] == "servos" and not all(_gains(r.actuators.get(k)) for k in ("kp", "kv")):
        p.append(must_be("record [actuators] kp and kv", "lists of finite gains >= 0, one per joint", r.actuators))
    if r.pd and not all(_gains(r.pd.get(k)) for k in ("kp", "kd")):
        p.append(must_be("record [pd] kp and kd", "lists of finite gains >= 0, one per joint", r.pd))
    elif r.pd and isinstance(r.joints, tuple) and not len(r.pd["kp"]) == len(r.pd["kd"]) == (len(r.joints) or
                                                                                             len(r.pd["kp"])):
        p.append(must_be("record [pd] kp and kd", f"{len(r.joints) or len(r.pd['kp'])} gains each, one per joint",
                         (len(r.pd["kp"]), len(r.pd["kd"]))))
    p += _reaching_problems(r.reaching)
    if r.visual not in VISUALS:
        p.append(must_be("record `visual`", f"one of {VISUALS}", r.visual))
    if r.collisions not in COLLISIONS:
        p.append(must_be("record `collisions`", f"one of {COLLISIONS}", r.collisions,
                         '"none": the arm collides with nothing; "model": as the model file says.'))
    return p


def _reaching_problems(reaching: dict) -> list[str]:
    p = []
    for key, unit in (("control_hz", "Hz"), ("duration_s", "s")):
        value = reaching.get(key, 1.0)
        if not (_finite([value]) and value > 0):
            p.append(must_be(f"record [reaching] {key}", f"a finite number > 0 ({unit})", value))
    models = reaching.get("models", [])
    if not (isinstance(models, list) and all(isinstance(m, str) and m for m in models)):
        p.append(must_be("record [reaching] models", "a list of modalities, e.g. [\"ee_xyz\", \"joints\"]", models))
    if reaching.get("actuators", "position") not in ("position", "torque"):
        p.append(must_be("record [reaching] actuators", "'position' or 'torque'", reaching.get("actuators")))
    if not isinstance(reaching.get("action", {}), dict):
        p.append(must_be("record [reaching] action", "a table of velocity controller settings", reaching["action"]))
    return p


def _ee_problems(ee: dict) -> list[str]:
    if ("site" in ee) == ("body" in ee) or not all(isinstance(ee.get(k, "x"), str) and ee.get(k, "x")
                                                   for k in ("site", "body")):
        return [must_be("record [ee]", "either site = NAME or body = NAME (with offset = [x, y, z] m)", ee)]
    if ee.get("body") == "world":
        return [must_be("record [ee] body", "a body the joints move", "world",
                        "Name the arm's last body (or a site on it).")]
    if "site" in ee and "offset" in ee:
        return [must_be("record [ee] offset", "given with a body only (a site is its own point)", ee)]
    offset = ee.get("offset", [0.0, 0.0, 0.0])
    if not (isinstance(offset, (list, tuple)) and len(offset) == 3 and _finite(offset)):
        return [must_be("record [ee] offset", "[x, y, z] in m in the body's frame", offset)]
    return []


def _camera_problems(camera: dict) -> list[str]:
    if not isinstance(camera, dict) or not isinstance(camera.get("name"), str) or not camera.get("name"):
        return [must_be("record [camera]", "name = a camera of the model, or name, pos, xyaxes, fovy", camera)]
    if "pos" not in camera:
        extra = sorted(set(camera) - {"name"})
        return [must_be("record [camera]", "name alone for a camera of the model", extra)] if extra else []
    pos, axes, fovy = camera.get("pos"), camera.get("xyaxes"), camera.get("fovy")
    if not (_vector(pos, 3) and _vector(axes, 6) and isinstance(fovy, (int, float)) and 0 < fovy < 180):
        return [must_be("record [camera]", "pos = [x, y, z] m, xyaxes = [6 numbers], fovy in (0, 180) deg", camera)]
    return []


def _workspace_problems(workspaces: dict) -> list[str]:
    if not isinstance(workspaces, dict) or not all(w in workspaces for w in REQUIRED_WORKSPACES):
        return [must_be("record [workspaces]", f"named joint boxes including {REQUIRED_WORKSPACES}",
                        sorted(workspaces) if isinstance(workspaces, dict) else workspaces)]
    for name, box in workspaces.items():
        if not (isinstance(box, tuple) and box and all(isinstance(r, tuple) and len(r) == 2 and _finite(r)
                                                       and r[0] < r[1] for r in box)):
            return [must_be(f"record workspace {name!r}", "[[lo, hi], ...] rad per joint with lo < hi", box)]
    return []


def _finite(values) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)


def _vector(v, n: int) -> bool:
    return isinstance(v, (list, tuple)) and len(v) == n and _finite(v)


def _gains(v) -> bool:
    return isinstance(v, (list, tuple)) and len(v) > 0 and _finite(v) and min(v) >= 0
