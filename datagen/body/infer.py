"""`infer_record`: the robot record of a bare MJCF/URDF, every value the file does not hold inferred.

- name: the file's own (URDF <robot name>, MJCF <mujoco model>), made a safe name; else the file's stem.
- ee and joints: the arm (`arm_chain.infer_arm`: the longest hinge chain ending in a hand, wrist or tool body,
  fingers and mimic joints left out; `--ee` and `--joints` as given); every other joint is held at its reference.
- workspaces: each joint's limits ("full" = "camera"); a continuous joint gets ±π, a range wider than a turn the
  turn around its middle.
- actuators: the model's own when every chosen joint has one; else position servos, critically damped, stiff
  enough for the joint's inertia (ω = SERVO_RAD_S) and to sag at most SAG_RAD under gravity.
- no PD gains: the torque baseline derives its own from the model at run time (control/pd_gains.py); a
  record's [pd] is a tuning someone wrote.
- camera: a camera of the model that sees the ee in ≥ GOOD_VIEW of the poses, else one placed to frame the ee's
  workspace (`place_camera`, from sampled forward kinematics), written into the record.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import mujoco
import numpy as np

from bodyschema.datagen.body.arm_chain import infer_arm
from bodyschema.datagen.body.build import build_model, compile_spec, read_source
from bodyschema.datagen.body.kinematics import ArmKinematics, fixed_camera
from bodyschema.datagen.body.model_files import parse_xml
from bodyschema.datagen.body.record import AUTO_CAMERA, SHIPPED, RobotRecord, load_record
from bodyschema.datagen.body.robot_checks import checked_image_size
from bodyschema.errors import must_be

IMAGE_SIZE = (64, 64)       # px: the default image of an inferred robot (small, quick to render and learn from)
FOVY_DEG = 45.0             # the placed camera's vertical field of view
FRAME_MARGIN = 0.85         # the ee workspace fills this fraction of the placed camera's half-image
SERVO_RAD_S = 20.0          # servo and PD natural frequency ω (rad/s): kp = I·ω², critically damped
SAG_RAD = 0.005             # a servo sags at most this far under gravity: kp ≥ max gravity torque / SAG_RAD
                            # (0.3°: ≈ 5 mm at a 1 m lever, under reaching's 10 mm bar; 0.05 sagged 25 mm on a UR5)
GOOD_VIEW = 0.9             # a model camera is kept when the ee is in view for this fraction of poses
MIN_VIEW = 0.2              # below: the camera does not see the arm (house error)
VIEW_SAMPLES = 512          # poses drawn (seed 0) to measure a camera's view and to place one
_PLACEHOLDER_CAMERA = {"name": AUTO_CAMERA, "pos": [0.0, 0.0, 1.0], "xyaxes": [1.0, 0, 0, 0, 1.0, 0], "fovy": FOVY_DEG}


def infer_record(path: Path, mesh_dir: Path | None = None, visual: str = "mesh",
                 image_size: tuple[int, int] = IMAGE_SIZE, ee: str | None = None,
                 joints: tuple[str, ...] = ()) -> RobotRecord:
    """A record of the model file at `path` with every value inferred (see the module docstring); `ee` (a body or
    site) and `joints` (hinges), when given, are used as they are."""
    path = Path(path).resolve()
    mesh = str(Path(mesh_dir).resolve()) if mesh_dir else ""
    box = ((-1.0, 1.0),)
    draft = RobotRecord(name=safe_name(path.stem), model=path.name, image_size=tuple(image_size), base=path.parent,
                        workspaces={"full": box, "camera": box}, camera=_PLACEHOLDER_CAMERA, mesh_dir=mesh,
                        visual=visual, collisions="none")
    spec, source = read_source(draft)
    model = compile_spec(spec, str(path), fusestatic=False)     # every body of the file, fixed ones too (a hand)
    ee, body, joints = infer_arm(model, ee, tuple(joints))
    if not joints:
        raise ValueError(must_be(f"the model {path}", "an arm with hinge joints up to its end effector",
                                 f"no hinge between the world and body {model.body(body).name!r}",
                                 "Name the end effector with --ee and the joints with --joints."))
    draft = dataclasses.replace(draft, name=file_name(source.text, path), ee=ee, joints=tuple(joints))
    built = build_model(draft)                            # the arm of the chosen hinges, welded, with its ee site
    ranges = _workspace(built.model)
    gains = inertia_gains(built.model, ranges, sag=True)
    actuated = {built.model.actuator(a).trnid[0] for a in range(built.model.nu)
                if built.model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT}
    actuators = {"kind": "model"} if actuated >= set(range(built.model.njnt)) else \
        {"kind": "servos", "kp": gains[0], "kv": gains[1]}
    box = tuple(map(tuple, ranges.tolist()))
    # no [pd]: the torque baseline derives its gains from the model at run time (control/pd_gains.py); a
    # [pd] in a record means someone tuned it
    draft = dataclasses.replace(draft, workspaces={"full": box, "camera": box}, actuators=actuators)
    return dataclasses.replace(draft, camera=_infer_camera(draft, spec, ranges))


def safe_name(stem: str) -> str:
    """A record name (`record_checks.NAME_PATTERN`) from a file's name or stem: other characters become '_'."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", stem).lstrip(".-")[:64]
    return name or "robot"


# ---- name ------------------------------------------------------------------------------------------------
def file_name(text: str, path: Path) -> str:
    """The robot's name as its file gives it (URDF <robot name>, MJCF <mujoco model>), made safe; else the stem
    (also for a format that is not XML: its reader has parsed the file already, so a parse error here means that)."""
    try:
        root = parse_xml(text, path, "model file")
    except ValueError:
        root = None
    given = root.get("name" if root.tag == "robot" else "model") if root is not None else None
    name = safe_name(given or path.stem)
    # a shipped robot's name would have its stores checked against the shipped model (example-robot-data's Panda)
    return f"{name}_{path.suffix.lstrip('.').lower()}" if name in SHIPPED else name


def _workspace(model: mujoco.MjModel) -> np.ndarray:
    """(Dq, 2) rad: the joint limits, at most one turn wide (around their middle)."""
    ranges = np.array(model.jnt_range, dtype=float)
    middle = ranges.mean(axis=1)
    return np.stack([np.maximum(ranges[:, 0], middle - np.pi), np.minimum(ranges[:, 1], middle + np.pi)], axis=1)


def inertia_gains(model: mujoco.MjModel, ranges: np.ndarray, sag: bool) -> tuple[list[float], list[float]]:
    """(kp N·m/rad, kd N·m·s/rad) per joint: kp = I·ω² (with `sag`: at least the largest gravity torque over
    sampled poses / SAG_RAD), kd = 2·√(kp·I) (critical damping); I the joint's largest diagonal inertia."""
    data, rng = mujoco.MjData(model), np.random.default_rng(0)
    inertia, gravity = np.zeros(model.nv), np.zeros(model.nv)
    full = np.zeros((model.nv, model.nv))
    for q in rng.uniform(ranges[:, 0], ranges[:, 1], (32, model.nq)):
        data.qpos[:], data.qvel[:] = q, 0.0
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, full)
        inertia = np.maximum(inertia, np.diag(full))                 # kg·m², armature included
        gravity = np.maximum(gravity, np.abs(data.qfrc_bias))        # N·m at rest
    inertia = np.maximum(inertia, 1e-6)
    kp = inertia * SERVO_RAD_S ** 2
    if sag:
        kp = np.maximum(kp, gravity / SAG_RAD)
    kd = 2.0 * np.sqrt(kp * inertia)
    return [float(round(k, 6)) for k in kp], [float(round(k, 6)) for k in kd]


# ---- the camera -------------------------------------------------------------------------------------------
def _infer_camera(draft: RobotRecord, spec: mujoco.MjSpec, ranges: np.ndarray) -> dict:
    best, name = 0.0, None
    for camera in (c.name for c in spec.cameras if c.name):
        fraction = view_fraction(ArmView(dataclasses.replace(draft, camera={"name": camera})), ranges)
        if fraction > best:
            best, name = fraction, camera
    if name is not None and best >= GOOD_VIEW:
        return {"name": name}
    return place_camera(ee_samples(ArmView(draft), ranges), draft.image_size)


class ArmView:
    """What placing a camera needs of a robot before a `Robot` of it exists (a Robot of a bare file is built from
    this inference): the ee's position (`fk`) and whether the record's camera sees it (`in_view`), computed as
    Robot computes them (kinematics.ArmKinematics, the camera at qpos0)."""

    def __init__(self, record: RobotRecord):
        built = build_model(record)
        model = built.model
        self.kinematics = ArmKinematics(model, model.site(built.ee_site).id)
        self.camera = fixed_camera(model, self.kinematics.data, model.camera(built.camera).id,
                                   checked_image_size(record.image_size))

    def fk(self, q, check: bool = False) -> np.ndarray:
        """As Robot.fk(q, check=False): the poses are drawn inside the joint limits, nothing to check."""
        return self.kinematics.fk(np.asarray(q, dtype=np.float64))

    def in_view(self, q) -> np.ndarray:
        return self.camera.sees(self.kinematics.fk_and_jacobian(np.asarray(q, dtype=np.float64))[0])


def ee_samples(robot, ranges: np.ndarray, n: int = VIEW_SAMPLES) -> np.ndarray:
    """(n, 3) m: the ee at n poses uniform in `ranges` (seed 0)."""
    q = np.random.default_rng(0).uniform(ranges[:, 0], ranges[:, 1], (n, len(ranges)))
    return robot.fk(q, check=False)


def view_fraction(robot, ranges: np.ndarray, n: int = VIEW_SAMPLES) -> float:
    """The fraction of n poses uniform in `ranges` (seed 0) whose ee the robot's camera sees."""
    q = np.random.default_rng(0).uniform(ranges[:, 0], ranges[:, 1], (n, len(ranges)))
    return float(robot.in_view(q).mean())


def check_view(robot, ranges: np.ndarray) -> float:
    """The view fraction; the house error when the camera sees the ee in fewer than MIN_VIEW of the poses."""
    fraction = view_fraction(robot, ranges)
    if fraction < MIN_VIEW:
        raise ValueError(must_be(f"camera {robot.camera_name!r} of robot {robot.name!r}",
                                 f"able to see the ee in at least {MIN_VIEW:.0%} of the sampled poses",
                                 f"{fraction:.1%}", "Choose another camera in the record, or let `bodyschema robot "
                                 f"init` place one ([camera] name = {AUTO_CAMERA!r} with its pose)."))
    return fraction


def place_camera(points: np.ndarray, image_size: tuple[int, int], fovy: float = FOVY_DEG,
                 view: np.ndarray | None = None, cover: float = 1.0) -> dict:
    """A camera pose framing `points` (N, 3) m: it looks along their direction of least spread (principal axes),
    from the side above them, with the widest spread along the image's longer side, far enough that every point
    falls inside FRAME_MARGIN of the image. `view` (3,): look along -view instead (the image's up as near the
    world's +z as it goes); `cover`: the fraction of the points framed (closer: the others may leave the image).
    Returns the record's [camera] values."""
    centre = (points.max(axis=0) + points.min(axis=0)) / 2
    spread = points - centre
    _, axes = np.linalg.eigh(spread.T @ spread)                  # columns by increasing variance
    h, w = image_size
    if view is not None:
        view = np.asarray(view, dtype=float) / np.linalg.norm(view)
        up = np.array([0.0, 0.0, 1.0]) if abs(view[2]) < 0.99 else axes[:, 2]
        y = up - (up @ view) * view
        y /= np.linalg.norm(y)
        x = np.cross(y, view)                                    # x × y = view (toward the camera)
    else:
        view, widest = axes[:, 0], axes[:, 2]
        if view[2] < 0 or (view[2] == 0 and view[0] < 0):        # come from above (else from +x)
            view = -view
        if w >= h:                                               # x (right) × y (up) = view (toward the camera)
            x = widest
            y = np.cross(view, x)
        else:
            y = widest
            x = np.cross(y, view)
        if y[2] < 0:                                             # keep the world's up upward in the image
            x, y = -x, -y
    tan_y = np.tan(np.deg2rad(fovy) / 2) * FRAME_MARGIN
    tan_x = tan_y * w / h
    along = spread @ view                                        # (N,) m toward the camera
    reach = np.maximum(np.abs(spread @ x) / tan_x, np.abs(spread @ y) / tan_y)
    distance = float(np.quantile(along + reach, cover)) + 0.05
    pos = centre + distance * view
    return {"name": AUTO_CAMERA, "pos": _rounded(pos), "xyaxes": _rounded(np.concatenate([x, y])), "fovy": fovy}


def _rounded(v: np.ndarray) -> list[float]:
    return [float(round(x, 6)) for x in v]


def robot_record(robot: str | Path | RobotRecord) -> RobotRecord:
    """The record of a robot reference: a record as is, a shipped name or file with its record, else inferred."""
    if isinstance(robot, RobotRecord):
        return robot
    record = load_record(robot)
    if record is None:
        record = infer_record(Path(robot))
    return record
