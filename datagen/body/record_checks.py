"""What a valid robot record holds: the values each key may take, and the house line for each one that is wrong.

`RobotRecord` runs `record_problems` as it is built, so a record that exists is valid. The tables a benchmark reads
(`BENCHMARK_SECTIONS`, e.g. [reaching]) are only checked to be tables here: their keys are the
benchmark's vocabulary, checked by the benchmark's reader (control/robot_defaults.py for [reaching]).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from bodyschema.datagen.body import formats
from bodyschema.errors import must_be

ACTUATORS = ("model", "servos")              # the model's own actuators | position servos added with [actuators] gains
VISUALS = ("mesh", "collision", "primitives")   # URDF: render the visual meshes | the collision geometry instead |
                                                # capsules and boxes from the links (no mesh read; datagen/primitives)
COLLISIONS = ("model", "none")               # contacts as the file has them | the arm's geoms collide with nothing
REQUIRED_WORKSPACES = ("full", "camera")     # every record names these two (datagen picks one by --images)
NAME_PATTERN = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")   # a file name everywhere: stores, models, runs
# tables a benchmark reads from a record, held as given: their keys are the benchmark's to check, not datagen's
BENCHMARK_SECTIONS = ("reaching",)
PLACED_KEYS = ("name", "pos", "xyaxes", "fovy")   # a placed camera's pose (in the world; a further camera may add
                                                  # `body`: then pos and xyaxes are in that body's frame)
MOUNTED_KEYS = ("body", "masked")            # a further camera riding on a link: the link; whether it sees only
                                             # the link and the bodies beyond (render_scope)


def record_problems(r) -> list[str]:
    """Every problem of a record's values (`r`: a `record.RobotRecord`, which calls this as it is built, so this
    module cannot import it), as house lines naming the key; [] for a valid record."""
    p = []
    if not (isinstance(r.name, str) and NAME_PATTERN.fullmatch(r.name)):
        p.append(must_be("record `name`", "1-64 letters, digits, '_', '-' or '.', not starting with '.' or '-'",
                         r.name, "It names stores, models and runs: e.g. my_arm."))
    for key in ("ee", "hold", "camera", "actuators", "pd", *BENCHMARK_SECTIONS, "workspaces"):
        if not isinstance(getattr(r, key), dict):
            return [*p, must_be(f"record `{key}`", f"a table ([{key}] with its keys)", getattr(r, key))]
    if not isinstance(r.mesh_dir, str):
        p.append(must_be("record `mesh_dir`", "a folder path (text), relative to the record", r.mesh_dir))
    if not (isinstance(r.model, str) and Path(r.model).suffix.lower() in formats.suffixes()):
        p.append(must_be("record `model`", f"a path to an {formats.described()} file", r.model,
                         "Other formats: convert them to one of these first (or add a reader: formats.py)."))
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
    p += _further_camera_problems(r.cameras, r.camera)
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
    if r.visual not in VISUALS:
        p.append(must_be("record `visual`", f"one of {VISUALS}", r.visual))
    if r.collisions not in COLLISIONS:
        p.append(must_be("record `collisions`", f"one of {COLLISIONS}", r.collisions,
                         '"none": the arm collides with nothing; "model": as the model file says.'))
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


def _further_camera_problems(cameras, camera: dict) -> list[str]:
    """`cameras`: further cameras with distinct names (each names a store array), not the main camera: a name of
    the model file's, or a placed pose as [camera] takes one."""
    from bodyschema.base.modalities import CAMERA_NAME
    if not isinstance(cameras, tuple):
        return [must_be("record `cameras`", "a list", cameras)]
    p = [problem for c in cameras if isinstance(c, dict) for problem in _camera_problems(c, mounted=True)
         if "pos" in c]
    p += [must_be("record `cameras` entry", "a camera name of the model file or {name, pos, xyaxes, fovy}", c)
          for c in cameras if isinstance(c, dict) and "pos" not in c]
    names = [c.get("name") if isinstance(c, dict) else c for c in cameras]
    if not all(isinstance(n, str) and CAMERA_NAME.fullmatch(n) for n in names) or len(set(names)) != len(names):
        p.append(must_be("record `cameras`", "distinct camera names (letters, digits, _ or -)", names,
                         'e.g. cameras = ["wrist"], or a placed one: cameras = [{name = "side", pos = [x, y, z], '
                         'xyaxes = [6 numbers], fovy = 45}]; each becomes the image modality image_<name>.'))
    elif isinstance(camera, dict) and camera.get("name") in names:
        p.append(must_be("record `cameras`", "further cameras, without the record's [camera]", camera["name"]))
    return p


def _camera_problems(camera: dict, mounted: bool = False) -> list[str]:
    """A placed camera's values; `mounted`: it may name the `body` it rides on (a further camera only: the record's
    [camera] gives ee_pixel and frames the workspace, so it stays fixed in the world)."""
    if not isinstance(camera, dict) or not isinstance(camera.get("name"), str) or not camera.get("name"):
        return [must_be("record [camera]", "name = a camera of the model, or name, pos, xyaxes, fovy", camera)]
    if "pos" not in camera:
        extra = sorted(set(camera) - {"name"})
        return [must_be("record [camera]", "name alone for a camera of the model", extra)] if extra else []
    allowed = [*PLACED_KEYS, *(MOUNTED_KEYS if mounted else ())]
    extra = sorted(set(camera) - set(allowed))
    if extra:
        hint = "A camera riding on a link goes in `cameras` (body = the link)." if "body" in extra else ""
        return [must_be(f"record camera {camera['name']!r}", f"keys among {allowed}", extra, hint)]
    pos, axes, fovy = camera.get("pos"), camera.get("xyaxes"), camera.get("fovy")
    if not (_vector(pos, 3) and _vector(axes, 6) and isinstance(fovy, (int, float)) and 0 < fovy < 180):
        return [must_be("record [camera]", "pos = [x, y, z] m, xyaxes = [6 numbers], fovy in (0, 180) deg", camera)]
    if "body" in camera and not (isinstance(camera["body"], str) and camera["body"]):
        return [must_be(f"record camera {camera['name']!r} body", "the name of a body of the model", camera["body"])]
    hint = "masked = true draws only the camera's link and the bodies beyond it."
    if "masked" in camera and "body" not in camera:
        return [must_be(f"record camera {camera['name']!r} masked", "on a camera riding on a link (with `body`)",
                        "a camera fixed in the world", hint)]
    if "masked" in camera and not isinstance(camera["masked"], bool):
        return [must_be(f"record camera {camera['name']!r} masked", "true or false", camera["masked"], hint)]
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
