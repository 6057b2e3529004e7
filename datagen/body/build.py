"""`build_model`: a robot record → the MuJoCo model the pipeline uses (an arm of the chosen hinges only).

From the model file (read by its format, formats.py: MJCF, URDF, ...) the spec is edited before it is compiled:
- every joint the record does not use is welded at its held value (`hold`, else its reference pose): its rotation
  (slide: its shift) is folded into its body's frame and the joint removed, with the actuators, sensors, equality
  constraints and keyframes that name it. A humanoid's free root is welded where the model puts it, so the
  chosen arm babbles on a fixed body, and qpos is exactly the chosen joint angles;
- a continuous hinge (no limits) gets the limits ±π;
- with `collisions = "none"` (what `robot init` writes) no geom of the arm collides, as in the shipped arms;
- the ee becomes a site (an ee given as a body plus an offset adds one, `record.EE_SITE`);
- a camera placed by the record is added to the world, or to the body a further camera names (`body`: a camera
  riding on a link), with a light beside the first when the model has none;
- with [actuators] kind = "servos" the chosen joints get position servos with the record's gains;
- `actuators="torque"` turns every actuator into a motor (ctrlrange = its force range, N·m).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import mujoco
import numpy as np

from bodyschema.datagen.body import formats
from bodyschema.datagen.body.model_files import Budget, check_spec, decode, one_line
from bodyschema.datagen.body.record import AUTO_CAMERA, EE_SITE, RobotRecord
from bodyschema.errors import must_be

ACTUATOR_KINDS = ("position", "torque")
_HINGE, _SLIDE = mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE


@dataclass(frozen=True)
class Source:
    """The model file as read: its text, its sha256, its meshes' (path as written → sha256) and, with
    `visual = "primitives"`, the links drawn as primitives with the meshes they replace."""

    path: str
    text: str
    sha256: str
    meshes: dict[str, str] = field(default_factory=dict)
    replaced: dict[str, list[str]] = field(default_factory=dict)


@dataclass(frozen=True)
class Built:
    model: mujoco.MjModel
    source: Source
    ee_site: str
    camera: str
    cameras: tuple[str, ...] = ()          # the record's further cameras, each checked to be the model's


def read_source(record: RobotRecord, text: str | None = None) -> tuple[mujoco.MjSpec, Source]:
    """The spec of the record's model file (or of `text`, the same file's content kept elsewhere) and its Source,
    every file read under the policy of `model_files` and the spec's sizes checked before anything is compiled."""
    path = record.model_path
    budget = Budget()
    if text is None:
        if not path.is_file():
            raise FileNotFoundError(must_be(f"the model file of robot {record.name!r}", "an existing file", str(path),
                                            "Fix `model` in its record (relative to the record's folder)."))
        raw = budget.read(path, f"the model file of robot {record.name!r}")
        text = decode(raw, path)
    else:
        raw = text.encode()
    spec, meshes, replaced = formats.of(path).read(path, text, record, budget)
    check_spec(spec, path)
    return spec, Source(str(path), text, hashlib.sha256(raw).hexdigest(), meshes, replaced)


def build_model(record: RobotRecord, actuators: str = "position", text: str | None = None) -> Built:
    """Compile the record's robot; `text` rebuilds it from the model file's kept content."""
    if actuators not in ACTUATOR_KINDS:
        raise ValueError(must_be("actuators", f"one of {ACTUATOR_KINDS}", actuators))
    spec, source = read_source(record, text)
    reference = compile_spec(spec, source.path, fusestatic=False)      # frames of every body, before any edit
    joints = chosen_joints(record, reference)
    _weld_others(spec, reference, joints, record.hold)
    _limit_continuous(spec, joints)
    if record.collisions == "none":
        _no_collisions(spec)
    site = _ee_site(spec, record.ee, record.name)
    camera = _camera(spec, record.camera, record.name)
    for further in record.cameras:
        if isinstance(further, dict):
            _camera(spec, further, record.name)
        else:
            _model_camera(spec, further, record.name, "cameras")
    if record.actuators["kind"] == "servos":
        _add_servos(spec, joints, record.actuators)
        _implicit_servo_damping(spec)
    if actuators == "torque":
        for act in spec.actuators:
            force = np.array(act.forcerange, dtype=float)
            act.set_to_motor()
            act.forcelimited, act.ctrlrange = mujoco.mjtLimited.mjLIMITED_FALSE, force
    if record.pd and len(record.pd["kp"]) != len(joints):
        raise ValueError(must_be(f"record [pd] kp and kd of robot {record.name!r}", f"{len(joints)} gains each, one "
                                 f"per joint of {joints}", (len(record.pd["kp"]), len(record.pd["kd"]))))
    model = compile_spec(spec, source.path)
    _check_ee_moves(model, site, record.name)
    return Built(model, source, site, camera, record.further_cameras)


def _check_ee_moves(model: mujoco.MjModel, site: str, robot: str) -> None:
    """The ee must hang below at least one of the chosen joints (on the world, its Jacobian is zero)."""
    body = int(model.site(site).bodyid[0])
    while body != 0 and not model.body_jntnum[body]:
        body = int(model.body_parentid[body])
    if body == 0:
        raise ValueError(must_be(f"the ee of robot {robot!r}", "moved by the chosen joints",
                                 f"site {site!r} on body {model.body(int(model.site(site).bodyid[0])).name!r}, "
                                 "which no chosen joint moves", "Fix [ee] in the record: name the arm's last body."))


def compile_spec(spec: mujoco.MjSpec, path: str, fusestatic: bool | None = None) -> mujoco.MjModel:
    saved = spec.compiler.fusestatic
    if fusestatic is not None:
        spec.compiler.fusestatic = fusestatic
    try:
        return spec.compile()
    except (ValueError, RuntimeError) as e:       # RuntimeError: "Caught an unknown exception!" (e.g. out of memory)
        raise ValueError(must_be(f"the model {path}", "one MuJoCo compiles", one_line(e))) from e
    finally:
        spec.compiler.fusestatic = saved


def chosen_joints(record: RobotRecord, model: mujoco.MjModel) -> list[str]:
    """The record's joints (every joint of the model when it names none), each checked to be a hinge."""
    names = [model.joint(j).name for j in range(model.njnt)]
    chosen = list(record.joints) or names
    for name in chosen:
        if name not in names:
            raise ValueError(must_be(f"joint {name!r} of robot {record.name!r}", f"one of {names}", name,
                                     "Fix `joints` in the record."))
        if model.jnt_type[model.joint(name).id] != _HINGE:
            kind = mujoco.mjtJoint(int(model.jnt_type[model.joint(name).id])).name.removeprefix("mjJNT_").lower()
            raise ValueError(must_be(f"joint {name!r} of robot {record.name!r}", "a hinge", f"a {kind} joint",
                                     "List only hinges in `joints`; others are held at [hold] or their reference."))
    return chosen


def _weld_others(spec: mujoco.MjSpec, model: mujoco.MjModel, keep: list[str], hold: dict[str, float]) -> None:
    """Fold each joint not in `keep` into its body's frame at its held value, then delete it and what names it."""
    unknown = sorted(set(hold) - {model.joint(j).name for j in range(model.njnt)})
    if unknown or set(hold) & set(keep):
        raise ValueError(must_be("record [hold]", "values of joints the model has and the record does not use",
                                 unknown or sorted(set(hold) & set(keep))))
    welded = [j for j in range(model.njnt) if model.joint(j).name not in keep]
    if not welded:
        return
    for body in sorted({int(model.jnt_bodyid[j]) for j in welded}):
        _fold_body(spec, model, body, set(welded), hold)
    names = {model.joint(j).name for j in welded}
    for j in sorted(welded, reverse=True):
        spec.delete(spec.joints[j])
    for act in list(spec.actuators):
        if act.trntype == mujoco.mjtTrn.mjTRN_JOINT and act.target in names:
            spec.delete(act)
    for sensor in list(spec.sensors):
        if sensor.objtype == mujoco.mjtObj.mjOBJ_JOINT and sensor.objname in names:
            spec.delete(sensor)
    for eq in list(spec.equalities):
        if eq.type == mujoco.mjtEq.mjEQ_JOINT and {eq.name1, eq.name2} & names:
            spec.delete(eq)
    for key in list(spec.keys):                   # their qpos no longer fits the model
        spec.delete(key)


def _fold_body(spec, model, body: int, welded: set[int], hold: dict[str, float]) -> None:
    """Body frame after its welded joints, as mj_kinematics composes it (engine_core_smooth.c)."""
    joints = list(np.flatnonzero(model.jnt_bodyid == body))
    held_first = [j in welded for j in joints]
    if held_first != sorted(held_first, reverse=True):
        raise ValueError(must_be(f"the joints of body {model.body(body).name!r}", "used ones after held ones",
                                 [model.joint(j).name for j in joints], "Use or hold them all."))
    pos, quat = np.array(model.body_pos[body]), np.array(model.body_quat[body])
    for j in (j for j in joints if j in welded):
        kind, name = int(model.jnt_type[j]), model.joint(j).name
        if name in hold and kind not in (_HINGE, _SLIDE):
            raise ValueError(must_be(f"record [hold] {name}", "a hinge or slide joint", "a ball or free joint",
                                     "Ball and free joints are held at their reference pose."))
        qpos0 = model.qpos0[model.jnt_qposadr[j]]
        delta = hold.get(name, qpos0) - qpos0 if kind in (_HINGE, _SLIDE) else 0.0
        if kind == _HINGE:
            turn = np.empty(4)
            mujoco.mju_axisAngle2Quat(turn, model.jnt_axis[j], delta)
            anchor = pos + _mat(quat) @ model.jnt_pos[j]
            mujoco.mju_mulQuat(quat, quat.copy(), turn)
            pos = anchor - _mat(quat) @ model.jnt_pos[j]
        elif kind == _SLIDE:
            pos = pos + _mat(quat) @ model.jnt_axis[j] * delta
    target = spec.joints[joints[0]].parent
    target.pos, target.quat = pos, quat / np.linalg.norm(quat)
    target.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT


def _no_collisions(spec: mujoco.MjSpec) -> None:
    """No geom on a body of the arm collides with anything (the world's own geoms, e.g. a floor, keep theirs)."""
    for geom in spec.geoms:
        if geom.parent.name != spec.worldbody.name:
            geom.contype = geom.conaffinity = 0


def _mat(quat: np.ndarray) -> np.ndarray:
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)


def _limit_continuous(spec: mujoco.MjSpec, joints: list[str]) -> None:
    half_turn = 180.0 if spec.compiler.degree else np.pi       # the MJCF's angle unit
    for name in joints:
        joint = spec.joint(name)
        if joint.limited == mujoco.mjtLimited.mjLIMITED_FALSE or (
                joint.limited == mujoco.mjtLimited.mjLIMITED_AUTO and joint.range[0] == joint.range[1] == 0):
            joint.limited, joint.range = mujoco.mjtLimited.mjLIMITED_TRUE, [-half_turn, half_turn]


def _ee_site(spec: mujoco.MjSpec, ee: dict, robot: str) -> str:
    if "site" in ee:
        if spec.site(ee["site"]) is None:
            sites = [s.name for s in spec.sites if s.name]
            raise ValueError(must_be("ee site", f"one of the model's sites {sites} for {robot}", ee["site"],
                                     "Fix [ee] in the record, or name a body: body = NAME, offset = [x, y, z] m."))
        return ee["site"]
    body = spec.body(ee["body"])
    if body is None:
        bodies = [b.name for b in spec.bodies if b.name and b.name != "world"]
        raise ValueError(must_be("ee body", f"one of the model's bodies {bodies} for {robot}", ee["body"],
                                 "Fix [ee] in the record."))
    body.add_site(name=EE_SITE, pos=list(ee.get("offset", [0.0, 0.0, 0.0])), size=[0.005, 0.005, 0.005])
    return EE_SITE


def _model_camera(spec: mujoco.MjSpec, name: str, robot: str, key: str = "camera") -> str:
    """name, when the model file has a camera of that name; else the house error listing the file's cameras."""
    if spec.camera(name) is None:
        names = [c.name for c in spec.cameras if c.name]
        hint = f"Or let `bodyschema robot init` place one (name = {AUTO_CAMERA!r})." if key == "camera" else \
            "Add the camera to the model file, or leave it out of the record's `cameras`."
        raise ValueError(must_be(key, f"one of the model's cameras {names} for {robot}", name, hint))
    return name


def _camera(spec: mujoco.MjSpec, camera: dict, robot: str) -> str:
    name = camera["name"]
    if "pos" not in camera:
        return _model_camera(spec, name, robot)
    x, y = np.array(camera["xyaxes"][:3], float), np.array(camera["xyaxes"][3:], float)
    x /= np.linalg.norm(x)
    y = y - (y @ x) * x
    y /= np.linalg.norm(y)
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.stack([x, y, np.cross(x, y)], axis=1).ravel())   # columns: camera axes in world
    _mount(spec, camera, robot).add_camera(name=name, pos=list(camera["pos"]), quat=quat, fovy=float(camera["fovy"]))
    if not spec.lights:                           # a model without lights (URDF) would render near black
        spec.worldbody.add_light(name=f"{name}_light", pos=list(camera["pos"]), dir=list(-np.cross(x, y)),
                                 diffuse=[0.8, 0.8, 0.8], ambient=[0.3, 0.3, 0.3])
    return name


def _mount(spec: mujoco.MjSpec, camera: dict, robot: str) -> mujoco.MjsBody:
    """The body a placed camera rides on: the world, or the record's `body` (pose in that body's frame)."""
    if "body" not in camera:
        return spec.worldbody
    body = spec.body(camera["body"])
    if body is None:
        bodies = [b.name for b in spec.bodies if b.name and b.name != "world"]
        raise ValueError(must_be(f"camera {camera['name']!r} body", f"one of the model's bodies {bodies} for {robot}",
                                 camera["body"], "Fix the camera's `body` in the record's `cameras`."))
    return body


def _implicit_servo_damping(spec: mujoco.MjSpec) -> None:
    """Servos we add are ours to keep stable: under MuJoCo's default Euler integrator a servo's velocity gain kv acts
    explicitly and diverges where timestep·kv/M_jj > 2 (TALOS's elbow near straight: 7; its joints swung at 13 rad/s
    for whole episodes). `implicitfast`, what the shipped MJCFs name, integrates that damping implicitly; a file that
    names another integrator keeps it."""
    if spec.option.integrator == mujoco.mjtIntegrator.mjINT_EULER:
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def _add_servos(spec: mujoco.MjSpec, joints: list[str], gains: dict) -> None:
    """Position servos on the chosen joints (ctrl = target angle, rad), replacing the model's actuators there."""
    if not len(gains["kp"]) == len(gains["kv"]) == len(joints):
        raise ValueError(must_be("record [actuators] kp and kv", f"{len(joints)} gains each, one per joint",
                                 (len(gains["kp"]), len(gains["kv"]))))
    for act in list(spec.actuators):
        if act.trntype == mujoco.mjtTrn.mjTRN_JOINT and act.target in joints:
            spec.delete(act)
    for name, kp, kv in zip(joints, gains["kp"], gains["kv"]):
        joint = spec.joint(name)
        act = spec.add_actuator(name=f"servo_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=float(kp), kv=float(kv), inheritrange=True)   # ctrlrange = the joint's range
        limit = float(kp) * np.pi              # what the servo pushes at half a turn of error, N·m
        if joint.actfrclimited == mujoco.mjtLimited.mjLIMITED_TRUE:
            limit = float(max(abs(joint.actfrcrange[0]), abs(joint.actfrcrange[1])))
        act.forcelimited, act.forcerange = mujoco.mjtLimited.mjLIMITED_TRUE, [-limit, limit]
