"""The `Robot` wrapper: an arm from a robot record, with batched forward kinematics, Jacobians, camera and rendering.

All arrays are numpy float64 and batched over N poses; q is in rad, positions in m, pixels in px as
(u = column, v = row) with pixel centres at integer coordinates and the origin at the top-left pixel.
Kinematic queries (fk, jacobian, render, observe, touch) run on a private MjData, so a caller stepping
dynamics on `robot.data` keeps its state. The renderer is created lazily (first render), so a `Robot` is
cheap to build in a worker process and its GL context belongs to the process that renders.
`fk`/`jacobian` call MuJoCo per pose (the reference); `observe` and the analytic model use the same hinge
recursion vectorized over the batch (`chain.HingeChain`, equal to 1e-12) when the batch is large.
What the model file does not say (ee, joints used, camera, image size, workspaces, actuators, gains) comes from
the robot's record (`robot_record.RobotRecord`); `robot_build.build_model` compiles the arm it describes. Each
robot names its workspaces (joint boxes, `robot.workspaces`); `sampling_ranges` is the one it was loaded with.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import mujoco
import numpy as np

from bodyschema.datagen.body.build import ACTUATOR_KINDS, Built, build_model
from bodyschema.datagen.body.camera import project
from bodyschema.datagen.body.chain import HingeChain
from bodyschema.datagen.body.record import RobotRecord, load_record, shipped_dir
from bodyschema.datagen.body.render_scope import render_model
from bodyschema.errors import must_be

IMAGE_SIZE_RANGE = (8, 1024)   # px, per side; the MJCF offscreen buffers are 1024 × 1024
LIMIT_TOLERANCE = 0.05         # rad; the simulator's soft joint limits let recorded q overshoot a little
GRAVITY = 9.81                 # m/s², default magnitude (downward, −z)
VECTORIZE_FROM = 256           # poses; smaller batches call MuJoCo per pose (numpy's per-op cost dominates)
DEFAULT_WORKSPACE = "camera"   # a Robot renders and projects: by default it samples the poses its camera sees
OFFSCREEN = 1024               # px: the offscreen buffer a model gets when its file asks for less
RENDER_POSES = 64              # poses (seed 0) over which the renderer's copy finds the moving meshes' nearest depth
_OPENCV_FROM_MUJOCO_CAM = np.diag([1.0, -1.0, -1.0])   # MuJoCo camera: x right, y up, looks along −z


def robot_record(robot: str | Path | RobotRecord) -> RobotRecord:
    """The record of a robot reference: a record as is, a shipped name or file with its record, else inferred."""
    if isinstance(robot, RobotRecord):
        return robot
    record = load_record(robot)
    if record is None:
        from bodyschema.datagen.body.infer import infer_record
        record = infer_record(Path(robot))
    return record


class Robot:
    """One robot arm: model + data, named joints, a fixed camera, and batched kinematic queries."""

    def __init__(self, record: RobotRecord, built: Built, image_size: tuple[int, int], rgb: bool, workspace: str):
        model = built.model
        self.record = record
        self.name = record.name
        self.model = model
        self.data = mujoco.MjData(model)                  # for the caller's dynamics
        self._kin = mujoco.MjData(model)                  # private: kinematic queries
        self.source = built.source                        # the model file: path, text, sha256, mesh digests
        self.mjcf_sha256 = built.source.sha256
        self.image_size = (int(image_size[0]), int(image_size[1]))
        self.channels = 3 if rgb else 1
        self.camera_name = built.camera
        self.ee_site = built.ee_site
        self.joint_names = tuple(model.joint(j).name for j in range(model.njnt))
        self.dq = len(self.joint_names)
        self.joint_limits = np.array(model.jnt_range, dtype=np.float64)            # (Dq, 2) rad
        hinges = (model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE).all()
        if not (hinges and model.nq == model.nv == model.njnt):
            raise ValueError(must_be(f"the model of {self.name}", "an arm of hinge joints only (qpos = joint angles)",
                                     f"nq={model.nq}, nv={model.nv}, njnt={model.njnt}"))
        self._site = model.site(self.ee_site).id
        self._qpos = self._kin.qpos                       # cached views into the private MjData (hot loops)
        self._ee = self._kin.site_xpos[self._site]
        self._cam = model.camera(self.camera_name).id
        touch = [s for s in range(model.nsensor) if model.sensor_type[s] == mujoco.mjtSensor.mjSENS_TOUCH]
        self._touch_adr = int(model.sensor_adr[touch[0]]) if touch else None
        self._position_actuated = bool(model.nu) and bool(np.all(model.actuator_biastype ==
                                                                 mujoco.mjtBias.mjBIAS_AFFINE))
        for box in record.workspaces.values():
            self.check_ranges(box)
        self.workspaces = {k: np.array(box, dtype=np.float64) for k, box in record.workspaces.items()}  # (Dq, 2) rad
        self.workspace = workspace                                                  # the one sampled from
        self.sampling_ranges = self.workspaces[workspace].copy()                    # (Dq, 2) rad
        self._renderer = None
        self._chain = HingeChain(model, self._site)
        self._camera_pose()

    # ---- pickling (a worker process gets its own copy) ----------------------------------------------------
    def __getstate__(self) -> dict:
        # _qpos and _ee are views into _kin: pickled they would become copies, and fk would write a pose no
        # kinematics reads (it returned the zero pose); the renderer holds a GL context
        return {k: v for k, v in vars(self).items() if k not in ("_qpos", "_ee", "_renderer")}

    def __setstate__(self, state: dict) -> None:
        vars(self).update(state)
        self._qpos = self._kin.qpos
        self._ee = self._kin.site_xpos[self._site]
        self._renderer = None

    # ---- construction --------------------------------------------------------------------------------
    @classmethod
    def load(cls, robot: str | Path | RobotRecord, image_size: tuple[int, int] | None = None, rgb: bool = False,
             gravity: float | None = None, actuators: str = "position", workspace: str | None = None,
             camera: str | None = None, text: str | None = None) -> "Robot":
        """Build a robot: a shipped name, a path to an MJCF/URDF (its record beside it, else inferred values) or
        to a record (.toml), or a RobotRecord. gravity: m/s² magnitude pointing down (None = 9.81).

        workspace: which named joint box of the record's workspaces becomes `sampling_ranges`;
        None = DEFAULT_WORKSPACE ("camera": the poses the camera sees, what rendering and ee_pixel need).
        Kinematics-only callers that want the whole reach pass "full" (datagen does with --no-images).
        camera: a camera of the model file; None = the record's camera (other cameras serve as baselines).
        text: the model file's content kept elsewhere (a store's attrs), read instead of the file.
        """
        record = robot_record(robot)
        workspace = DEFAULT_WORKSPACE if workspace is None else workspace
        if workspace not in record.workspaces:
            raise ValueError(must_be("workspace", f"one of {tuple(record.workspaces)} for {record.name}", workspace,
                                     "Pass ranges explicitly for another joint box."))
        image_size = _check_image_size(record.image_size if image_size is None else image_size)
        if actuators not in ACTUATOR_KINDS:
            raise ValueError(must_be("actuators", f"one of {ACTUATOR_KINDS}", actuators))
        gravity = GRAVITY if gravity is None else _finite_float(gravity)
        if not (gravity is not None and gravity >= 0):
            raise ValueError(must_be("gravity", "a finite magnitude >= 0 in m/s^2", gravity,
                                     "Pass 0 for no gravity; it always points down (-z)."))
        if camera is not None and camera != record.camera_name:
            record = _with_camera(record, camera)
        built = build_model(record, actuators, text)
        built.model.opt.gravity[:] = (0.0, 0.0, -float(gravity))
        _fit_offscreen(built.model, image_size)
        return cls(record, built, image_size, rgb, workspace)

    @classmethod
    def from_attrs(cls, attrs: dict, **kwargs) -> "Robot":
        """The robot a store was made with, from its attrs alone (record and model text; see `robot_attrs`)."""
        from bodyschema.datagen.body.attrs import check_meshes, record_of_attrs
        record, text = record_of_attrs(attrs)
        if "image_size" not in kwargs:                   # a model's body has no camera size: its caller gives it
            kwargs["image_size"] = tuple(attrs["image_size"])
        kwargs.setdefault("rgb", attrs.get("channels") == 3)
        robot = cls.load(record, text=text, **kwargs)
        check_meshes(robot, attrs)
        return robot

    def check_ranges(self, ranges) -> None:
        """Raise the house ValueError unless `ranges` (Dq, 2) rad are ordered and inside the joint limits."""
        try:
            r = np.asarray(ranges, dtype=np.float64)
        except (TypeError, ValueError):
            r = None
        if r is None or r.shape != (self.dq, 2) or not np.isfinite(r).all():
            raise ValueError(must_be("sampling ranges", f"a finite array of shape ({self.dq}, 2) in rad", ranges,
                                     f"One [low, high] per joint of {list(self.joint_names)}."))
        for j, (lo, hi) in enumerate(r):
            jlo, jhi = self.joint_limits[j]
            if not (jlo <= lo < hi <= jhi):
                raise ValueError(must_be(f"sampling range of {self.joint_names[j]}",
                                         f"ordered and inside the joint limits [{jlo:.4f}, {jhi:.4f}] rad",
                                         [float(lo), float(hi)], f"Fix the range in the record of {self.name}."))

    # ---- camera --------------------------------------------------------------------------------------
    def _camera_pose(self) -> None:
        # Cameras are fixed in the world: compute the pose once at qpos0 (mj_camlight sets cam_xpos/xmat).
        mujoco.mj_kinematics(self.model, self._kin)
        mujoco.mj_camlight(self.model, self._kin)
        rot = _OPENCV_FROM_MUJOCO_CAM @ self._kin.cam_xmat[self._cam].reshape(3, 3).T   # world → camera
        self._rot = rot
        self._trans = -rot @ self._kin.cam_xpos[self._cam]
        h, w = self.image_size
        f = 0.5 * h / np.tan(0.5 * np.deg2rad(self.model.cam_fovy[self._cam]))   # px, square pixels
        self._K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])

    def intrinsics(self) -> np.ndarray:
        """K (3, 3) in px for the configured image size."""
        return self._K.copy()

    def extrinsics(self) -> np.ndarray:
        """(4, 4) world → camera, OpenCV convention (x right, y down, z forward)."""
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = self._rot, self._trans
        return t

    def project(self, xyz) -> np.ndarray:
        """(N, 3) m world → (N, 2) px (u = column, v = row)."""
        return project(self._K, self.extrinsics(), self._check_points(xyz))

    def in_view(self, q) -> np.ndarray:
        """(N, Dq) rad → (N,) bool: the ee lies in front of the camera and projects inside the image."""
        xyz = self._fk_and_jacobian(self.check_q(q))[0]                  # (N, 3) m
        depth = xyz @ self._rot[2] + self._trans[2]                      # (N,) m along the optical axis
        px = project(self._K, self.extrinsics(), xyz)                    # (N, 2) px
        h, w = self.image_size
        return (depth > 0) & (px >= 0).all(axis=1) & (px[:, 0] <= w - 1) & (px[:, 1] <= h - 1)

    def project_jacobian(self, xyz) -> np.ndarray:
        """(N, 3) m → (N, 2, 3) d px / d m of `project`."""
        xyz = self._check_points(xyz)
        cam = xyz @ self._rot.T + self._trans                            # (N, 3)
        f = self._K[0, 0]
        inv_z = 1.0 / cam[:, 2:3]                                        # (N, 1)
        # d(X/Z)/dx = (R₀ − (X/Z) R₂) / Z, likewise for Y
        du = f * (self._rot[0][None] - cam[:, 0:1] * inv_z * self._rot[2][None]) * inv_z   # (N, 3)
        dv = f * (self._rot[1][None] - cam[:, 1:2] * inv_z * self._rot[2][None]) * inv_z
        return np.stack([du, dv], axis=1)

    # ---- kinematics ----------------------------------------------------------------------------------
    def fk(self, q, check: bool = True) -> np.ndarray:
        """(N, Dq) rad → (N, 3) m, the `ee` site position in the world (mj_kinematics per pose).

        check=False skips `check_q` (shape, finiteness, joint limits): for simulated states, which may pass the
        limits by a little, in hot loops."""
        return self._fk(self.check_q(q) if check else np.asarray(q, dtype=np.float64))

    def jacobian(self, q, check: bool = True) -> np.ndarray:
        """(N, Dq) rad → (N, 3, Dq) m/rad, d ee / d q from mj_jacSite; check as in `fk`."""
        return self._jacobian(self.check_q(q) if check else np.asarray(q, dtype=np.float64))

    def fk_and_jacobian(self, q, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(N, Dq) rad → ee (N, 3) m and d ee / d q (N, 3, Dq) m/rad, the fastest way: vectorized over the hinge
        chain for large batches (≥ VECTORIZE_FROM poses), MuJoCo per pose otherwise; check as in `fk`."""
        return self._fk_and_jacobian(self.check_q(q) if check else np.asarray(q, dtype=np.float64))

    @property
    def actuation(self) -> str:
        """What the actuators take: "position" (servos: ctrl is a joint target, rad) or "torque" (motors: ctrl is
        a joint torque, N·m); `Robot.load(actuators=...)` chose it."""
        return "position" if self._position_actuated else "torque"

    def _fk(self, q: np.ndarray) -> np.ndarray:
        m, d, qpos, ee, kinematics = self.model, self._kin, self._qpos, self._ee, mujoco.mj_kinematics
        out = np.empty((q.shape[0], 3))
        for q_i, out_i in zip(q, out):
            qpos[:] = q_i
            kinematics(m, d)
            out_i[:] = ee
        return out

    def _jacobian(self, q: np.ndarray) -> np.ndarray:
        return self._mj_fk_and_jacobian(q)[1]

    def _fk_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unchecked (any finite q, limits not enforced): (N, 3) m and (N, 3, Dq) m/rad, the fastest way."""
        return self._chain(q) if q.shape[0] >= VECTORIZE_FROM else self._mj_fk_and_jacobian(q)

    def _mj_fk_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference: mj_kinematics + mj_comPos + mj_jacSite per pose."""
        m, d, qpos, ee, site = self.model, self._kin, self._qpos, self._ee, self._site
        kinematics, com_pos, jac_site = mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_jacSite
        xyz, jac = np.empty((q.shape[0], 3)), np.empty((q.shape[0], 3, self.dq))
        for q_i, xyz_i, jac_i in zip(q, xyz, jac):
            qpos[:] = q_i
            kinematics(m, d)
            com_pos(m, d)                                 # cdof and subtree_com, used by mj_jacSite
            xyz_i[:] = ee
            jac_site(m, d, jac_i, None, site)             # writes the (3, nv = Dq) row block in place
        return xyz, jac

    # ---- sensing -------------------------------------------------------------------------------------
    def render(self, q, check: bool = True) -> np.ndarray:
        """(N, Dq) rad → (N, H, W) uint8 grayscale or (N, H, W, 3) uint8 RGB from the fixed camera; check as in
        `fk`."""
        return self._render(self.check_q(q) if check else np.asarray(q, dtype=np.float64))

    def _render(self, q: np.ndarray) -> np.ndarray:
        renderer, camera, rgb_buf = self._ensure_renderer()
        m, d, qpos = self.model, self._kin, self._qpos
        h, w = self.image_size
        images = np.empty((q.shape[0], h, w, 3) if self.channels == 3 else (q.shape[0], h, w), dtype=np.uint8)
        for q_i, image_i in zip(q, images):
            qpos[:] = q_i
            mujoco.mj_kinematics(m, d)
            mujoco.mj_camlight(m, d)
            renderer.update_scene(d, camera)
            if self.channels == 3:
                renderer.render(out=image_i)
            else:                                         # ITU-R BT.601 luma, as cv2
                cv2.cvtColor(renderer.render(out=rgb_buf), cv2.COLOR_RGB2GRAY, dst=image_i)
        return images

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensor modalities (rows of base/modalities.py) `observe` reads for this robot."""
        return ("touch",) if self._touch_adr is not None else ()

    def touch(self, q) -> np.ndarray | None:
        """(N, Dq) rad → (N, 1) fingertip touch (N) with the arm held at q at rest; None without a sensor."""
        if self._touch_adr is None:
            return None
        return self._touch(self.check_q(q))

    def _touch(self, q: np.ndarray) -> np.ndarray:
        m, d, out = self.model, self._kin, np.empty((q.shape[0], 1))
        d.qvel[:] = 0.0
        for i in range(q.shape[0]):
            d.qpos[:] = q[i]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_collision(m, d)                     # cheap pre-check: no contact → no touch
            if d.ncon == 0:
                out[i, 0] = 0.0
                continue
            d.ctrl[:] = q[i] if self._position_actuated else 0.0    # position servos hold the pose
            mujoco.mj_forward(m, d)
            out[i, 0] = d.sensordata[self._touch_adr]
        return out

    def observe(self, q, image: bool = True) -> dict[str, np.ndarray]:
        """All observations of a batch: ee_xyz (N,3) m, ee_pixel (N,2) px, jacobian (N,3,Dq) m/rad as float32,
        image (N,H,W[,3]) uint8 when `image`, touch (N,1) float32 when the robot has a touch sensor."""
        q = self.check_q(q)
        xyz, jac = self._fk_and_jacobian(q)
        out = {"ee_xyz": xyz.astype(np.float32), "ee_pixel": self.project(xyz).astype(np.float32),
               "jacobian": jac.astype(np.float32)}
        if image:
            out["image"] = self._render(q)
        if self._touch_adr is not None:
            out["touch"] = self._touch(q).astype(np.float32)
        return out

    def _ensure_renderer(self):
        if self._renderer is None:
            h, w = self.image_size
            ranges = self.workspaces["full"]
            poses = np.random.default_rng(0).uniform(ranges[:, 0], ranges[:, 1], (RENDER_POSES, self.dq))
            shipped = self.record.model_path.parent == shipped_dir().resolve()
            scene = render_model(self.model, self._cam, self.image_size, poses, simplify=not shipped)
            self._renderer = mujoco.Renderer(scene, height=h, width=w)
            self._mjv_camera = mujoco.MjvCamera()
            self._mjv_camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
            self._mjv_camera.fixedcamid = self._cam
            self._rgb_buf = np.empty((h, w, 3), dtype=np.uint8)
        return self._renderer, self._mjv_camera, self._rgb_buf

    def close(self) -> None:
        """Free the GL context (if one was created)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return (f"Robot({self.name!r}, joints={list(self.joint_names)}, image_size={self.image_size}, "
                f"channels={self.channels}, camera={self.camera_name!r}, workspace={self.workspace!r})")

    # ---- validation ----------------------------------------------------------------------------------
    def check_q(self, q) -> np.ndarray:
        """Return q as a float64 (N, Dq) array; raise the house ValueError on bad shape, NaN or limits."""
        q = np.asarray(q, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != self.dq:
            raise ValueError(must_be("q", f"an array of shape (N, {self.dq}) in rad for joints "
                                     f"{list(self.joint_names)}", q.shape, "Add a batch axis with q[None]."))
        if not np.isfinite(q).all():
            raise ValueError(must_be("q", "finite", "NaN or inf values"))
        low, high = self.joint_limits[:, 0] - LIMIT_TOLERANCE, self.joint_limits[:, 1] + LIMIT_TOLERANCE
        bad = np.nonzero((q < low) | (q > high))
        if bad[0].size:
            i, j = bad[0][0], bad[1][0]
            raise ValueError(must_be(f"q[:, {j}] ({self.joint_names[j]})",
                                     f"inside the joint limits {self.joint_limits[j].round(4).tolist()} rad",
                                     f"{q[i, j]:.4f} at row {i} ({bad[0].size} values outside)",
                                     "Sample inside robot.sampling_ranges."))
        return q

    def _check_points(self, xyz) -> np.ndarray:
        xyz = np.asarray(xyz, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3 or not np.isfinite(xyz).all():
            raise ValueError(must_be("xyz", "a finite array of shape (N, 3) in m", xyz.shape))
        return xyz


def _finite_float(x) -> float | None:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def _check_image_size(size) -> tuple[int, int]:
    lo, hi = IMAGE_SIZE_RANGE
    try:
        h, w = (int(s) for s in size)
        ok = all(float(s) == int(s) for s in size) and lo <= h <= hi and lo <= w <= hi
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(must_be("image_size", f"(H, W) with each side an integer in [{lo}, {hi}] px", size))
    return h, w


def _with_camera(record: RobotRecord, camera: str) -> RobotRecord:
    """The record looking through another camera of the model file."""
    return dataclasses.replace(record, camera={"name": camera})


def _fit_offscreen(model: mujoco.MjModel, image_size: tuple[int, int]) -> None:
    """A model file that asks for a small offscreen buffer (URDF: none) gets one the image fits in."""
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), OFFSCREEN, image_size[1])
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), OFFSCREEN, image_size[0])
