"""Fingertip touch: the contact force (N) a model's touch sensor reads with the arm held at rest at each pose q."""

from __future__ import annotations

import mujoco
import numpy as np


def touch_address(model: mujoco.MjModel) -> int | None:
    """Where the model's first touch sensor writes in sensordata; None for a model without one."""
    touch = [s for s in range(model.nsensor) if model.sensor_type[s] == mujoco.mjtSensor.mjSENS_TOUCH]
    return int(model.sensor_adr[touch[0]]) if touch else None


def touch_at_rest(model: mujoco.MjModel, data: mujoco.MjData, address: int, position_actuated: bool,
                  q: np.ndarray) -> np.ndarray:
    """(N, Dq) rad → (N, 1) N: the sensor at `address` with the arm at rest at each q (servos hold the pose)."""
    m, d, out = model, data, np.empty((q.shape[0], 1))
    d.qvel[:] = 0.0
    for i in range(q.shape[0]):
        d.qpos[:] = q[i]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)                     # cheap pre-check: no contact → no touch
        if d.ncon == 0:
            out[i, 0] = 0.0
            continue
        d.ctrl[:] = q[i] if position_actuated else 0.0    # position servos hold the pose
        mujoco.mj_forward(m, d)
        out[i, 0] = d.sensordata[address]
    return out
