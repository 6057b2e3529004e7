"""The `Robot` wrapper: an arm from a robot record, with batched forward kinematics, Jacobians, camera and rendering.

All arrays are numpy float64 and batched over N poses; q is in rad, positions in m, pixels in px as
(u = column, v = row) with pixel centres at integer coordinates and the origin at the top-left pixel.
Kinematic queries (fk, jacobian, render, observe, touch) run on a private MjData, so a caller stepping
dynamics on `robot.data` keeps its state. Images: `robot_render` (a renderer made on the first render, in the
process that renders); the camera's geometry: `camera.FixedCamera`; argument checks: `robot_checks`.
Kinematics: `kinematics.ArmKinematics` (`fk`/`jacobian` call MuJoCo per pose, the reference; `observe` and the
analytic model use the hinge recursion vectorized over the batch, equal to 1e-12, when the batch is large).
What the model file does not say (ee, joints used, camera, image size, workspaces, actuators, gains) comes from
the robot's record (`record.RobotRecord`, `infer.robot_record`); `build.build_model` compiles the arm. Each
robot names its workspaces (joint boxes, `robot.workspaces`); `sampling_ranges` is the one it was loaded with.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import mujoco
import numpy as np

from bodyschema.base.modalities import EE_PIXEL, IMAGE, camera_modality, pixel_modality
from bodyschema.datagen.body.build import ACTUATOR_KINDS, Built, build_model
from bodyschema.datagen.body.infer import robot_record
from bodyschema.datagen.body.kinematics import ArmKinematics, camera_moves, fixed_camera
from bodyschema.datagen.body.record import RobotRecord, shipped_dir
from bodyschema.datagen.body.robot_checks import check_ranges, checked_image_size, checked_points, finite_float
from bodyschema.datagen.body.robot_render import CameraRenderer, fit_offscreen
from bodyschema.datagen.body.touch import touch_address, touch_at_rest
from bodyschema.errors import must_be

LIMIT_TOLERANCE = 0.05         # rad; the simulator's soft joint limits let recorded q overshoot a little
GRAVITY = 9.81                 # m/s², default magnitude (downward, −z)
DEFAULT_WORKSPACE = "camera"   # a Robot renders and projects: by default it samples the poses its camera sees


class Robot:
    """One robot arm: model + data, named joints, a fixed camera, and batched kinematic queries."""

    def __init__(self, record: RobotRecord, built: Built, image_size: tuple[int, int], rgb: bool, workspace: str):
        model = built.model
        self.record = record
        self.name = record.name
        self.model = model
        self.data = mujoco.MjData(model)                  # for the caller's dynamics
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
        self._kinematics = ArmKinematics(model, model.site(self.ee_site).id)
        self._kin = self._kinematics.data                 # private: kinematic queries, renders, touch
        self._cam = model.camera(self.camera_name).id
        # image modality → camera id: the robot's own ("image"), then the record's further cameras (image_<name>)
        self.cameras = {IMAGE: self._cam, **{camera_modality(c): model.camera(c).id for c in built.cameras}}
        self._touch_adr = touch_address(model)
        self._position_actuated = bool(model.nu) and bool(np.all(model.actuator_biastype ==
                                                                 mujoco.mjtBias.mjBIAS_AFFINE))
        for box in record.workspaces.values():
            self.check_ranges(box)
        self.workspaces = {k: np.array(box, dtype=np.float64) for k, box in record.workspaces.items()}  # (Dq, 2) rad
        self.workspace = workspace                                                  # the one sampled from
        self.sampling_ranges = self.workspaces[workspace].copy()                    # (Dq, 2) rad
        self._renderers: dict[str, CameraRenderer] = {}
        if camera_moves(model, self._cam):
            raise ValueError(must_be(f"camera {self.camera_name!r} of {self.name}", "a camera fixed in the world",
                                     "a camera that moves with the arm", "It gives ee_pixel and frames the "
                                     "workspace: name a camera riding on a link in the record's `cameras` instead."))
        # ee projection modality → its camera's view: ee_pixel (the robot's own), ee_pixel_<name> (further cameras
        # fixed in the world; one riding on a link has no fixed projection, so no ee_pixel_<name>)
        self._views = {pixel_modality(m): fixed_camera(model, self._kin, cam, self.image_size)
                       for m, cam in self.cameras.items() if not camera_moves(model, cam)}

    # ---- pickling (a worker process gets its own copy) ----------------------------------------------------
    def __getstate__(self) -> dict:
        return {k: v for k, v in vars(self).items() if k != "_renderers"}    # a renderer holds a GL context

    def __setstate__(self, state: dict) -> None:
        vars(self).update(state)
        self._renderers = {}

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
        image_size = checked_image_size(record.image_size if image_size is None else image_size)
        if actuators not in ACTUATOR_KINDS:
            raise ValueError(must_be("actuators", f"one of {ACTUATOR_KINDS}", actuators))
        gravity = GRAVITY if gravity is None else finite_float(gravity)
        if not (gravity is not None and gravity >= 0):
            raise ValueError(must_be("gravity", "a finite magnitude >= 0 in m/s^2", gravity,
                                     "Pass 0 for no gravity; it always points down (-z)."))
        if camera is not None and camera != record.camera_name:
            record = _with_camera(record, camera)
        built = build_model(record, actuators, text)
        built.model.opt.gravity[:] = (0.0, 0.0, -float(gravity))
        fit_offscreen(built.model, image_size)
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
        check_ranges(ranges, self.joint_names, self.joint_limits, self.name)

    # ---- camera --------------------------------------------------------------------------------------
    def intrinsics(self, modality: str = EE_PIXEL) -> np.ndarray:
        """K (3, 3) in px for the configured image size, of the camera of the projection `modality`
        (ee_pixel: the robot's own; ee_pixel_<name>: a further camera's)."""
        return self._view_of(modality).K.copy()

    def extrinsics(self, modality: str = EE_PIXEL) -> np.ndarray:
        """(4, 4) world → camera, OpenCV convention (x right, y down, z forward); camera as `intrinsics`."""
        return self._view_of(modality).extrinsics()

    def project(self, xyz, modality: str = EE_PIXEL) -> np.ndarray:
        """(N, 3) m world → (N, 2) px (u = column, v = row) in the camera of the projection `modality`."""
        return self._view_of(modality).project(checked_points(xyz))

    def projections(self) -> tuple[str, ...]:
        """The ee projection modalities of this robot: ee_pixel, then ee_pixel_<name> per further camera."""
        return tuple(self._views)

    def _view_of(self, modality: str):
        if modality not in self._views:
            raise ValueError(must_be("modality", f"one of {self.name}'s projections {list(self._views)}", modality,
                                     "Name further cameras in the robot record's `cameras`."))
        return self._views[modality]

    def in_view(self, q) -> np.ndarray:
        """(N, Dq) rad → (N,) bool: the ee lies in front of the camera and projects inside the image."""
        return self._views[EE_PIXEL].sees(self._fk_and_jacobian(self.check_q(q))[0])

    def project_jacobian(self, xyz, modality: str = EE_PIXEL) -> np.ndarray:
        """(N, 3) m → (N, 2, 3) d px / d m of `project`."""
        return self._view_of(modality).project_jacobian(checked_points(xyz))

    # ---- kinematics ----------------------------------------------------------------------------------
    def _checked(self, q, check: bool) -> np.ndarray:
        """q as float64 (N, Dq), through `check_q` when `check` (every public query's `check` flag)."""
        return self.check_q(q) if check else np.asarray(q, dtype=np.float64)

    def fk(self, q, check: bool = True) -> np.ndarray:
        """(N, Dq) rad → (N, 3) m, the `ee` site position in the world (mj_kinematics per pose).

        check=False skips `check_q` (shape, finiteness, joint limits): for simulated states, which may pass the
        limits by a little, in hot loops."""
        return self._fk(self._checked(q, check))

    def jacobian(self, q, check: bool = True) -> np.ndarray:
        """(N, Dq) rad → (N, 3, Dq) m/rad, d ee / d q from mj_jacSite; check as in `fk`."""
        return self._jacobian(self._checked(q, check))

    def fk_and_jacobian(self, q, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(N, Dq) rad → ee (N, 3) m and d ee / d q (N, 3, Dq) m/rad, the fastest way: vectorized over the hinge
        chain for large batches (≥ VECTORIZE_FROM poses), MuJoCo per pose otherwise; check as in `fk`."""
        return self._fk_and_jacobian(self._checked(q, check))

    def ee_rot(self, q, check: bool = True) -> np.ndarray:
        """(N, Dq) rad → the `ee` site's orientation as its rotation matrix read row by row (N, 9) (the ee_rot
        modality: entry 3i + k is world axis i's component of the site's axis k); check as in `fk`."""
        rot = self._kinematics.rotation(self._checked(q, check))
        return rot.reshape(len(rot), 9)

    def ee_rot_and_jacobian(self, q, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """`ee_rot` and its derivative (N, 9, Dq) per rad; check as in `fk`."""
        rot, jac = self._kinematics.rotation_and_jacobian(self._checked(q, check))
        return rot.reshape(len(rot), 9), jac.reshape(len(jac), 9, self.dq)

    @property
    def actuation(self) -> str:
        """What the actuators take: "position" (servos: ctrl is a joint target, rad) or "torque" (motors: ctrl is
        a joint torque, N·m); `Robot.load(actuators=...)` chose it."""
        return "position" if self._position_actuated else "torque"

    def _fk(self, q: np.ndarray) -> np.ndarray:
        return self._kinematics.fk(q)

    def _jacobian(self, q: np.ndarray) -> np.ndarray:
        return self._kinematics.mj_fk_and_jacobian(q)[1]

    def _fk_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._kinematics.fk_and_jacobian(q)

    # ---- sensing -------------------------------------------------------------------------------------
    def render(self, q, check: bool = True, modality: str = IMAGE) -> np.ndarray:
        """(N, Dq) rad → (N, H, W) uint8 grayscale or (N, H, W, 3) uint8 RGB from the fixed camera of `modality`
        (the robot's own, or a further camera's image_<name>: `cameras`); check as in `fk`."""
        if modality not in self.cameras:
            raise ValueError(must_be("modality", f"one of {self.name}'s cameras {list(self.cameras)}", modality,
                                     "Name further cameras in the robot record's `cameras`."))
        return self._render(self._checked(q, check), modality)

    def _render(self, q: np.ndarray, modality: str = IMAGE) -> np.ndarray:
        return self._ensure_renderer(modality).render(self.model, self._kin, q)

    @property
    def sensors(self) -> tuple[str, ...]:
        """What `observe` reads for this robot beyond its kinematics and its own camera: sensor rows of
        base/modalities.py, its further cameras' image modalities (those only with images) and the ee's projection
        into each further camera fixed in the world."""
        return (*(("touch",) if self._touch_adr is not None else ()), *list(self.cameras)[1:],
                *self.projections()[1:])

    def touch(self, q) -> np.ndarray | None:
        """(N, Dq) rad → (N, 1) fingertip touch (N) with the arm held at q at rest; None without a sensor."""
        if self._touch_adr is None:
            return None
        return self._touch(self.check_q(q))

    def _touch(self, q: np.ndarray) -> np.ndarray:
        return touch_at_rest(self.model, self._kin, self._touch_adr, self._position_actuated, q)

    def observe(self, q, image: bool = True) -> dict[str, np.ndarray]:
        """All observations of a batch: ee_xyz (N,3) m, ee_rot (N,9), ee_pixel (N,2) px and each further camera's
        ee_pixel_<name>, jacobian (N,3,Dq) m/rad as float32, image (N,H,W[,3]) uint8 and each further camera's
        image_<name> when `image`, touch (N,1) float32 when the robot has a touch sensor."""
        q = self.check_q(q)
        xyz, jac = self._fk_and_jacobian(q)
        out = {"ee_xyz": xyz.astype(np.float32), "ee_rot": self.ee_rot(q, check=False).astype(np.float32),
               **{m: view.project(xyz).astype(np.float32) for m, view in self._views.items()},
               "jacobian": jac.astype(np.float32)}
        if image:
            out.update({modality: self._render(q, modality) for modality in self.cameras})
        if self._touch_adr is not None:
            out["touch"] = self._touch(q).astype(np.float32)
        return out

    def _ensure_renderer(self, modality: str = IMAGE) -> CameraRenderer:
        if modality not in self._renderers:
            shipped = self.record.model_path.parent == shipped_dir().resolve()
            masked = {camera_modality(c["name"]) for c in self.record.cameras
                      if isinstance(c, dict) and c.get("masked")}
            self._renderers[modality] = CameraRenderer(self.model, self.cameras[modality], self.image_size,
                                                       self.channels, self.workspaces["full"], simplify=not shipped,
                                                       masked=modality in masked)
        return self._renderers[modality]

    def close(self) -> None:
        """Free the GL contexts (of the renderers created)."""
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers = {}

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


def _with_camera(record: RobotRecord, camera: str) -> RobotRecord:
    """The record looking through another camera of the model file."""
    return dataclasses.replace(record, camera={"name": camera})
