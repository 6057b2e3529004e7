"""Forward kinematics and site Jacobian of a MuJoCo hinge chain in numpy, vectorized over a batch of poses: the
site's position and its orientation, each with its derivative in the joints.

For large batches this is several times faster than calling mj_kinematics + mj_jacSite per pose; `Robot`
switches to it from `VECTORIZE_FROM` poses up (kinematics.py).
"""

from __future__ import annotations

import mujoco
import numpy as np


class HingeChain:
    """mj_kinematics' recursion for the hinge chain from the world to the `ee` site, vectorized over poses.

    Per body (parents first): x_b = x_parent + R_parent·body_pos, R_b = R_parent·R(body_quat); each hinge j
    then turns the body frame by (q_j − qpos0_j) about its local axis, keeping the anchor
    p_j = x_b + R_b·jnt_pos fixed (MuJoCo engine_core_smooth.c, mj_kinematics). The site Jacobian column is
    a_j × (x_ee − p_j) with the world axis a_j = R_b·axis_j, as mj_jacSite gives for hinges.
    Equal to the per-pose MuJoCo calls to ~1e-14 (tested).
    """

    def __init__(self, model: mujoco.MjModel, site: int):
        body, path = int(model.site_bodyid[site]), []
        while body != 0:
            path.append(body)
            body = int(model.body_parentid[body])
        self.path = path[::-1]                                                  # world's child first
        self.body_pos = np.array(model.body_pos)                                # (nbody, 3) m
        self.body_rot = np.array([quat_to_mat(quat) for quat in model.body_quat])   # (nbody, 3, 3)
        self.joints = {b: np.nonzero(model.jnt_bodyid == b)[0] for b in self.path}
        self.jnt_pos, self.jnt_axis = np.array(model.jnt_pos), np.array(model.jnt_axis)
        self.qpos0, self.qadr = np.array(model.qpos0), np.array(model.jnt_qposadr)
        self.site_pos = np.array(model.site_pos[site])
        self.site_rot = quat_to_mat(model.site_quat[site])                        # the site in its body
        self.dq = model.njnt
        # Rodrigues about the local axis a: R(θ) = I + sin θ·[a]× + (1 − cos θ)·[a]×²   (constant [a]×, [a]×²)
        self.skew = np.array([-np.cross(np.eye(3), axis).T for axis in self.jnt_axis])  # (Dq, 3, 3): [a]×v = a × v
        self.skew2 = self.skew @ self.skew

    def __call__(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, Dq) rad → the site's position (N, 3) m and its Jacobian (N, 3, Dq) m/rad."""
        xyz, _, anchors, axes = self._walk(q)
        jac = np.cross(axes, xyz[None] - anchors)                               # (Dq, N, 3) m/rad
        return xyz, jac.transpose(1, 2, 0)                                      # (N, 3), (N, 3, Dq)

    def rotation(self, q: np.ndarray) -> np.ndarray:
        """(N, Dq) rad → the site's orientation R (N, 3, 3): its axes as columns, in the world, as MuJoCo's
        site_xmat."""
        return self._walk(q)[1]

    def rotation_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`rotation` and dR/dq (N, 3, 3, Dq): a hinge turns R about its world axis a_j, dR/dq_j = [a_j]× R."""
        _, rot, _, axes = self._walk(q)
        turned = np.cross(axes[:, :, :, None], rot[None], axis=2)               # (Dq, N, 3, 3): a_j × each column
        return rot, turned.transpose(1, 2, 3, 0)

    def _walk(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The site's position (N, 3) and orientation (N, 3, 3), each hinge's anchor and world axis (Dq, N, 3)."""
        n = q.shape[0]
        pos, rot = np.zeros((n, 3)), np.broadcast_to(np.eye(3), (n, 3, 3))     # (N, 3) m, (N, 3, 3)
        anchors, axes = np.zeros((self.dq, n, 3)), np.zeros((self.dq, n, 3))
        for b in self.path:
            pos = pos + np.einsum("nij,j->ni", rot, self.body_pos[b])
            rot = rot @ self.body_rot[b]
            for j in self.joints[b]:
                anchors[j] = pos + np.einsum("nij,j->ni", rot, self.jnt_pos[j])
                axes[j] = np.einsum("nij,j->ni", rot, self.jnt_axis[j])
                angle = q[:, self.qadr[j]] - self.qpos0[self.qadr[j]]                  # (N,) rad
                turn = np.eye(3) + np.sin(angle)[:, None, None] * self.skew[j] \
                    + (1.0 - np.cos(angle))[:, None, None] * self.skew2[j]             # (N, 3, 3)
                rot = rot @ turn
                if self.jnt_pos[j].any():                                               # off-centre hinge
                    pos = anchors[j] - np.einsum("nij,j->ni", rot, self.jnt_pos[j])
        xyz = pos + np.einsum("nij,j->ni", rot, self.site_pos)                  # (N, 3) m
        return xyz, rot @ self.site_rot, anchors, axes


def quat_to_mat(quat: np.ndarray) -> np.ndarray:
    mat = np.empty(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=np.float64))
    return mat.reshape(3, 3)
