"""The spaces of a reaching environment, with bounds the arm cannot leave (or that the env clips to, said where).

    joints    rad   the joint limits widened by LIMIT_TOLERANCE: the simulator's soft limits let an arm pushed
                    into a limit pass it a little (`Robot.check_q` accepts as much); beyond that it is clipped
    ee_xyz    m     the box around the arm's reach sphere (first joint's anchor ± the sum of its link lengths)
    ee_pixel  px    the camera image, [0, W − 1] × [0, H − 1]: an ee out of view is clipped to the border
    image     uint8 the camera image (H, W) or (H, W, 3)
    goal            the goal modality's own space: a pose inside the joint limits, an ee inside the reach box, a
                    pixel inside the image, an image
Actions: float32 in [-1, 1] per actuator (what Gymnasium's and SB3's checkers ask of a continuous action), mapped
affinely onto the native box: position servo targets (their ctrlrange, rad), motor torques (their ctrlrange, N·m) or
joint velocity commands (± the velocity controller's max_velocity, rad/s); -1 is the low end, +1 the high one, 0 the
middle (a torque range symmetric about 0 keeps 0 N·m at 0). `native_action_space` is that box (float64).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from bodyschema.base import modalities
from bodyschema.datagen.body.reach import arm_reach
from bodyschema.datagen.body.robot import LIMIT_TOLERANCE

GOALS = ("ee_xyz", "ee_pixel", "joints", "image")   # the goal modalities, as reaching's
ACTIONS = ("position", "torque", "velocity")


def _box(low, high) -> spaces.Box:
    return spaces.Box(np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64), dtype=np.float64)


def joints_bounds(robot) -> np.ndarray:
    """(Dq, 2) rad: what the joints observation may hold."""
    widen = np.array([-LIMIT_TOLERANCE, LIMIT_TOLERANCE])
    return robot.joint_limits + widen


def reach_bounds(robot) -> np.ndarray:
    """(3, 2) m: the box around the arm's reach sphere."""
    base, reach = arm_reach(robot.model, robot.ee_site)
    return np.stack([base - reach, base + reach], axis=1)


def pixel_bounds(robot) -> np.ndarray:
    """(2, 2) px: (u, v) inside the image."""
    h, w = robot.image_size
    return np.array([[0.0, w - 1.0], [0.0, h - 1.0]])


def image_space(robot) -> spaces.Box:
    shape = (*robot.image_size, 3) if robot.channels == 3 else tuple(robot.image_size)
    return spaces.Box(0, 255, shape, dtype=np.uint8)


def modality_space(robot, modality: str) -> spaces.Box:
    if modalities.is_image(modality):
        return image_space(robot)
    bounds = {"joints": joints_bounds, "ee_xyz": reach_bounds, "ee_pixel": pixel_bounds}[modality](robot)
    return _box(bounds[:, 0], bounds[:, 1])


def observation_space(robot, goal: str, image: bool) -> spaces.Dict:
    keys = ("joints", "ee_xyz", "ee_pixel", *(("image",) if image else ()))
    return spaces.Dict({**{k: modality_space(robot, k) for k in keys}, "goal": modality_space(robot, goal)})


def action_space(robot, action: str, max_velocity: float) -> spaces.Box:
    if action == "velocity":
        return _box(np.full(robot.dq, -max_velocity), np.full(robot.dq, max_velocity))
    low, high = robot.model.actuator_ctrlrange.T
    return _box(low, high)


def normalized_space(native: spaces.Box) -> spaces.Box:
    """The action space an agent sees: float32 [-1, 1] of the native box's shape."""
    return spaces.Box(-1.0, 1.0, native.shape, dtype=np.float32)


def to_native(native: spaces.Box, action: np.ndarray) -> np.ndarray:
    """(nu,) in [-1, 1] (clipped there first) → float64 in the native box: low + (a + 1) / 2 · (high − low)."""
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    return native.low + (a + 1.0) * 0.5 * (native.high - native.low)


def to_normalized(native: spaces.Box, command: np.ndarray) -> np.ndarray:
    """The inverse of to_native: a native command (clipped into its box) → float32 in [-1, 1]; an actuator whose
    range is one value maps to 0."""
    x = np.clip(np.asarray(command, dtype=np.float64), native.low, native.high)
    width = native.high - native.low
    a = np.divide(2.0 * (x - native.low), width, out=np.ones_like(x), where=width > 0) - 1.0
    return np.clip(a, -1.0, 1.0).astype(np.float32)


def clip_to(space: spaces.Box, x: np.ndarray) -> np.ndarray:
    """x (*shape) in the space's dtype, clipped into its bounds (a fresh array: gymnasium wants no shared data)."""
    return np.clip(x, space.low, space.high).astype(space.dtype)
