"""`arm_reach`: the base point and reach (m) of a serial hinge arm, the physical bounds `validate_store` checks.

For a chain of hinges with anchors p_1 … p_D (world → hand) and the hand site x, the distance between consecutive
points never changes with q (each hinge turns everything after it about an axis through its own anchor), so
    |x − p_1| ≤ R = Σ_j |p_{j+1} − p_j| + |x − p_D|      at every pose,
and each Jacobian column a_j × (x − p_j) (unit axis a_j) has norm ≤ |x − p_j| ≤ R: |J| ≤ R m/rad.
The distances are measured once, at the model's reference pose.
"""

from __future__ import annotations

import mujoco
import numpy as np


def arm_reach(model: mujoco.MjModel, site: str = "ee") -> tuple[np.ndarray, float]:
    """(3,) m the first joint's anchor (fixed in the world) and R m, the longest |hand − base| at any pose."""
    site_id = model.site(site).id
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)  # anchors and the site at qpos0
    bodies, body = [], int(model.site_bodyid[site_id])
    while body != 0:
        bodies.append(body)
        body = int(model.body_parentid[body])
    joints = [j for b in reversed(bodies) for j in np.flatnonzero(model.jnt_bodyid == b)]  # world → hand order
    points = np.array([data.xanchor[j] for j in joints] + [data.site_xpos[site_id]])  # (D + 1, 3) m
    reach = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
    return points[0].copy(), reach
