"""`observability(robot)`: how much the camera image changes per degree of each chosen joint, at typical poses.

A pixel decoder can only perceive a joint whose motion changes its image: on a 7-joint arm the pixel floors were
1.6, 0.8, 4.9, 4.2, 44 and 52° per joint, the two wrists unseen because the arm covered 4 % of the image at the
inferred framing. The camera, not the network, is the lever there, and this is the figure that says so before any
data is made or any model trained.

At `n` poses uniform in the camera workspace (seeded, the generator passed in), each chosen joint is moved by ±δ
and the images are compared with the pose's own (same size and colour as the record's images, grey by BT.601):
- px/°: pixels whose grey value changes by more than CHANGED_GREY, per degree (the mean over poses and signs);
- %/°: the same as a share of the image's pixels (px/° ÷ H·W), a figure of the framing that the image size leaves
  alone (SO-101's joints: 0.61, 0.63, 0.47, 0.24 %/° at 128×128, 0.63, 0.67, 0.50, 0.26 at 64×64);
- mm/°: how far the ee moves per degree (forward kinematics);
- the fraction of the image the moving arm covers (segmentation render), and of poses whose ee is in the image.
A joint under MIN_SHARE_PER_DEG or MIN_PX_PER_DEG, or whose axis the ee lies on (a roll about the tool's own axis,
whatever its px/°), is flagged (`weak`); see the constants for why those values: of the two figures, the floors
followed the share, and a larger image raises only the count.
Cost: n·(1 + 2·Dq) renders at the record's image size (16 poses, 6 joints, 64×64: 208 renders, ≈ 0.2-0.5 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

DELTA_DEG = 2.0          # the perturbation: the 2° a perceived joint should be resolved to
POSES = 16               # typical poses sampled (uniform in the camera workspace)
CHANGED_GREY = 8         # grey levels (of 255): a change below this is within a trained pixel decoder's error
                         # (held-out RMSE 0.037 ≈ 9.4 levels on a UR5, README "Your own robot"), so it is not counted
MIN_PX_PER_DEG = 10.0    # px/°: below, too few pixels change for a decoder to draw the motion. Measured on the
                         # README's UR5 (64×64, its placed camera, 5 joints): 40.9, 50.4, 30.1, 5.2 and 2.2 px/° at
                         # pixel-decoder floors of 1.2, 0.9, 2.3, 15.7 and 55°: under 10 px/° the floor is ≥ 5°
MIN_SHARE_PER_DEG = 0.25 # %/° of the image: below, a joint is not seen at any image size. 10 px/° of a 64×64 image,
                         # where MIN_PX_PER_DEG was measured, as a share: a larger image raised the pixel count and not
                         # the floor (the UR5's wrist_1 passed at 128×128 with 10.1 px/°, 0.06 %/°, and floored at
                         # 168°; SO-101 on 20 000 poses: 1.46, 2.02, 3.47, 8.02° at 128×128 against 2.21, 3.12, 5.00,
                         # 9.67° at 64×64, 1.2–1.5× apart where its px/° are 4× apart). Above it, 2° needs more share
                         # as the arm has more joints: at 80 000 poses (64×64, lean, 40 epochs) SO-101 (5 joints)
                         # floored at 1.13, 1.63, 3.41, 7.18° with 0.63, 0.67, 0.50, 0.26 %/°, Z1 (6 joints) at 2.61,
                         # 3.87, 5.71, 13.8, 8.64° with 0.89, 0.97, 0.61, 0.30, 0.29 %/°
ROLL_MM = 10.0           # mm: an ee this close to a joint's axis is on it (a roll about the tool's own axis). Such a
                         # roll changes the image only by the tool's asymmetry, and no decoder here learned one at
                         # any px/°: floors of 109–169° (SO-101's wrist_roll at 14.6 px/°, the UR5's wrist_3, both
                         # Pandas' joint 7, Jaco's last joint; README "On the defaults: nine arms")
_BT601 = np.array([0.299, 0.587, 0.114])


@dataclass(frozen=True)
class JointView:
    name: str
    px_per_deg: float       # pixels changed (> CHANGED_GREY) per degree, mean over poses and ±δ
    share_per_deg: float    # the same as a percentage of the image's pixels, %/°
    mm_per_deg: float       # ee displacement per degree, mm, mean over poses
    axis_mm: float          # the ee's mean distance from the joint's axis, mm (≈ mm/° · 180/π)

    @property
    def on_axis(self) -> bool:
        """The ee lies on this joint's axis: a roll about the tool's own axis."""
        return self.axis_mm < ROLL_MM

    @property
    def few_pixels(self) -> bool:
        """Under MIN_PX_PER_DEG: too few pixels change for a decoder to draw the motion (a larger image helps)."""
        return self.px_per_deg < MIN_PX_PER_DEG

    @property
    def small_share(self) -> bool:
        """Under MIN_SHARE_PER_DEG: too small a part of the image changes (a larger image does not help)."""
        return self.share_per_deg < MIN_SHARE_PER_DEG

    @property
    def weak(self) -> bool:
        """Not seen: too few pixels, too small a share of the image, or a roll about the tool's own axis."""
        return self.few_pixels or self.small_share or self.on_axis

    def why(self) -> str:
        """Why a weak joint is not seen, from its geometry."""
        if self.on_axis:
            return (f"the ee lies on its axis ({self.axis_mm:.1f} mm off, {self.mm_per_deg:.2f} mm/°): a roll about "
                    "the tool's own axis, seen only through bodies beyond it that are not round about that axis")
        if self.small_share:
            return (f"it moves the ee {self.mm_per_deg:.2f} mm/°, but the pixels it changes are "
                    f"{self.share_per_deg:.2f} % of the image per degree (the bodies it moves are small or hidden "
                    "behind the arm at this framing), and a larger image keeps that share: move the camera closer (a "
                    "narrower workspace, `robot camera`), or add a second view for it (`robot camera --add`)")
        return (f"it moves the ee {self.mm_per_deg:.2f} mm/°, and changes {self.share_per_deg:.2f} % of the image per "
                "degree, but in too few pixels at this image size: raise image_size (`robot camera "
                "--max-image-size`)")


@dataclass(frozen=True)
class Observability:
    joints: tuple[JointView, ...]
    arm_fraction: float         # mean fraction of the image's pixels showing the moving arm
    in_view: float | None       # fraction of poses whose ee projects inside the image (the robot's own camera)
    image_size: tuple[int, int]
    camera: str
    poses: int

    @property
    def weak(self) -> tuple[JointView, ...]:
        return tuple(j for j in self.joints if j.weak)

    @property
    def weakest(self) -> JointView:
        return min(self.joints, key=lambda j: j.px_per_deg)

    def table(self) -> str:
        h, w = self.image_size
        width = max(len(j.name) for j in self.joints)
        in_view = "" if self.in_view is None else f", ee in view {self.in_view:.1%}"
        lines = [f"observability: camera {self.camera!r}, {h}×{w} px, {self.poses} poses, ±{DELTA_DEG:g}°: the arm "
                 f"covers {self.arm_fraction:.1%} of the image{in_view}",
                 f"  {'joint':<{width}}   px/°     %/°    mm/°",
                 *(f"  {j.name:<{width}} {j.px_per_deg:7.1f} {j.share_per_deg:7.2f} {j.mm_per_deg:7.2f}{_flag(j)}"
                   for j in self.joints),
                 f"  (px/°: pixels whose grey value changes by > {CHANGED_GREY}/255 per degree, %/°: as a share of "
                 f"the image; under {MIN_SHARE_PER_DEG:g} %/° or {MIN_PX_PER_DEG:g} px/° a joint is not perceived to "
                 "2° from this camera; above, 2° takes a larger share the more joints the arm has)"]
        return "\n".join(lines)

    def warnings(self) -> list[str]:
        """The house warning per weak joint: the joint, its figure and why."""
        return [self.warning(j) for j in self.weak]

    def warning(self, joint: JointView) -> str:
        from bodyschema.errors import must_be
        return must_be(f"joint {joint.name!r} seen by camera {self.camera!r}", *_expected_and_got(joint),
                       f"Not seen: {joint.why()}.")


def best_views(views) -> tuple[Observability, ...]:
    """Per joint, the view (of one robot's cameras at one image size) that changes the largest share of its image:
    where that view does not see it, none does."""
    return tuple(max(views, key=lambda view: view.joints[i].share_per_deg) for i in range(len(views[0].joints)))


def unseen_warnings(views) -> list[str]:
    """The house warning per joint that none of a robot's cameras (`views`, one Observability each) sees, from the
    camera that sees it best: a joint one camera sees is seen (perception sums the cameras' errors)."""
    return [view.warning(view.joints[i]) for i, view in enumerate(best_views(views)) if view.joints[i].weak]


def _flag(joint: JointView) -> str:
    """The table's mark of a joint not seen, and which rule."""
    if joint.on_axis:
        return "   on its axis: not seen"
    if joint.small_share:
        return f"   < {MIN_SHARE_PER_DEG:g} %/°: not seen"
    return f"   < {MIN_PX_PER_DEG:g} px/°: not seen" if joint.few_pixels else ""


def _expected_and_got(joint: JointView) -> tuple[str, str]:
    """The house warning's expectation and figure for a joint not seen."""
    if joint.on_axis:
        return ("a joint that moves the ee, to be perceived from an image",
                f"{joint.mm_per_deg:.2f} mm/° ({joint.axis_mm:.1f} mm off its axis; {joint.px_per_deg:.1f} px/°)")
    if joint.small_share:
        return (f"at least {MIN_SHARE_PER_DEG:g} % of the image changed per degree to be perceived to 2°",
                f"{joint.share_per_deg:.2f} %/° ({joint.px_per_deg:.1f} px/°)")
    return (f"at least {MIN_PX_PER_DEG:g} pixels changed per degree to be perceived to 2°",
            f"{joint.px_per_deg:.2f} px/°")


def observability(robot, ranges: np.ndarray | None = None, rng: np.random.Generator | None = None,
                  n: int = POSES, delta_deg: float = DELTA_DEG, modality: str = "image") -> Observability:
    """Per chosen joint of `robot` (the camera of `modality`: its own, or a further camera's image_<name>; its image
    size and colour), the image change and ee motion per degree at n poses uniform in `ranges` (Dq, 2) rad (None:
    its sampling ranges), seed from `rng` (None: seed 0)."""
    from bodyschema.datagen.body.infer import view_fraction

    ranges = np.asarray(robot.sampling_ranges if ranges is None else ranges, dtype=np.float64)   # (Dq, 2) rad
    rng = np.random.default_rng(0) if rng is None else rng
    delta = np.deg2rad(delta_deg)
    inner = np.stack([ranges[:, 0] + delta, ranges[:, 1] - delta], axis=1)      # ±δ stays in the box
    inner = np.where(inner[:, :1] <= inner[:, 1:], inner, ranges.mean(axis=1, keepdims=True))
    q = rng.uniform(inner[:, 0], inner[:, 1], (n, robot.dq))                     # (n, Dq) rad
    steps = np.concatenate([np.eye(robot.dq), -np.eye(robot.dq)]) * delta        # (2Dq, Dq)
    moved = (q[:, None, :] + steps[None]).reshape(-1, robot.dq)                  # (n·2Dq, Dq)
    base = _grey(robot.render(q, check=False, modality=modality))                # (n, H, W)
    other = _grey(robot.render(moved, check=False, modality=modality)).reshape(n, 2, robot.dq, *base.shape[1:])
    changed = (np.abs(other - base[:, None, None]) > CHANGED_GREY).sum(axis=(-2, -1))         # (n, ±, Dq)
    px = changed.mean(axis=(0, 1)) / delta_deg                                                # (Dq,)
    jac = robot.jacobian(q, check=False)                                          # (n, 3, Dq) m/rad
    arm = np.linalg.norm(jac, axis=1)                                             # (n, Dq) m/rad: the lever
    mm = arm.mean(axis=0) * 1e3 * np.pi / 180                                     # (Dq,) mm/°
    share = 100 * px / base[0].size                                              # (Dq,) %/° of the image
    joints = tuple(JointView(name, float(p), float(s), float(m), float(a)) for name, p, s, m, a
                   in zip(robot.joint_names, px, share, mm, arm.mean(axis=0) * 1e3))
    own = modality == "image"
    camera = robot.camera_name if own else robot.model.camera(robot.cameras[modality]).name
    return Observability(joints, arm_fraction(robot, q, modality), view_fraction(robot, ranges) if own else None,
                         tuple(robot.image_size), camera, n)


def every_camera(robot, ranges: np.ndarray | None = None) -> list[Observability]:
    """`observability` through each camera of `robot` (its own, then the record's further ones), seed 0."""
    return [observability(robot, ranges, np.random.default_rng(0), modality=modality) for modality in robot.cameras]


def arm_fraction(robot, q: np.ndarray, modality: str = "image") -> float:
    """The mean fraction of image pixels that show a body moved by a chosen joint, at poses q (n, Dq) rad, through
    the camera of `modality`: moved relative to the camera (a camera riding on a link does not see its link move)."""
    view = robot._ensure_renderer(modality)
    renderer, camera = view.renderer, view.camera
    model = robot.model
    weld = model.body_weldid[model.geom_bodyid]                        # (ngeom,): held bodies weld to the world
    moving = (weld != 0) & (weld != model.body_weldid[model.cam_bodyid[robot.cameras[modality]]])
    data = mujoco.MjData(model)
    covered = []
    renderer.enable_segmentation_rendering()
    try:
        for q_i in q:
            data.qpos[:] = q_i
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            renderer.update_scene(data, camera)
            seg = renderer.render()                                     # (H, W, 2): object id, object type
            geom = (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & (seg[..., 0] >= 0)
            ids = np.where(geom, seg[..., 0], 0)
            covered.append(float((geom & moving[ids]).mean()))
    finally:
        renderer.disable_segmentation_rendering()
    return float(np.mean(covered))


def _grey(images: np.ndarray) -> np.ndarray:
    """(N, H, W[, 3]) uint8 → (N, H, W) float grey levels (BT.601 for colour, as datagen renders grey)."""
    return images @ _BT601 if images.ndim == 4 else images.astype(np.float64)
