"""`ArmKinematics`: the ee site's position, orientation and Jacobians over a batch of poses, on a private MjData.

`fk` calls MuJoCo per pose (mj_kinematics: the reference); `fk_and_jacobian` uses the same hinge recursion
vectorized over the batch (`chain.HingeChain`, equal to 1e-12) from VECTORIZE_FROM poses up, MuJoCo per pose
(mj_kinematics + mj_comPos + mj_jacSite) below; `rotation` (the site's orientation) and its Jacobian the chain always.
`Robot` queries through it, and so does `robot init`'s camera placement (infer.py) before any Robot exists.
"""

from __future__ import annotations

import mujoco
import numpy as np

from bodyschema.datagen.body.camera import FixedCamera
from bodyschema.datagen.body.chain import HingeChain

VECTORIZE_FROM = 256           # poses; smaller batches call MuJoCo per pose (numpy's per-op cost dominates)


class ArmKinematics:
    def __init__(self, model: mujoco.MjModel, site: int):
        self.model, self.site = model, site
        self.data = mujoco.MjData(model)                  # private: kinematic queries (and the robot's renders)
        self.dq = model.njnt
        self._chain = HingeChain(model, site)
        self._bind()

    def _bind(self) -> None:
        self._qpos = self.data.qpos                       # cached views into the private MjData (hot loops)
        self._ee = self.data.site_xpos[self.site]

    # _qpos and _ee are views into data: pickled they would become copies, and fk would write a pose no kinematics
    # reads (it returned the zero pose)
    def __getstate__(self) -> dict:
        return {k: v for k, v in vars(self).items() if k not in ("_qpos", "_ee")}

    def __setstate__(self, state: dict) -> None:
        vars(self).update(state)
        self._bind()

    def fk(self, q: np.ndarray) -> np.ndarray:
        """(N, Dq) rad, unchecked → (N, 3) m."""
        m, d, qpos, ee, kinematics = self.model, self.data, self._qpos, self._ee, mujoco.mj_kinematics
        out = np.empty((q.shape[0], 3))
        for q_i, out_i in zip(q, out):
            qpos[:] = q_i
            kinematics(m, d)
            out_i[:] = ee
        return out

    def fk_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unchecked (any finite q, limits not enforced): (N, 3) m and (N, 3, Dq) m/rad, the fastest way."""
        return self._chain(q) if q.shape[0] >= VECTORIZE_FROM else self.mj_fk_and_jacobian(q)

    def rotation(self, q: np.ndarray) -> np.ndarray:
        """Unchecked: the site's orientation (N, 3, 3) (MuJoCo's site_xmat), by the vectorized chain at every batch
        size (no caller needs it per pose at camera rate)."""
        return self._chain.rotation(q)

    def rotation_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unchecked: `rotation` and its derivative (N, 3, 3, Dq) per rad."""
        return self._chain.rotation_and_jacobian(q)

    def mj_fk_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reference: mj_kinematics + mj_comPos + mj_jacSite per pose."""
        m, d, qpos, ee, site = self.model, self.data, self._qpos, self._ee, self.site
        kinematics, com_pos, jac_site = mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_jacSite
        xyz, jac = np.empty((q.shape[0], 3)), np.empty((q.shape[0], 3, self.dq))
        for q_i, xyz_i, jac_i in zip(q, xyz, jac):
            qpos[:] = q_i
            kinematics(m, d)
            com_pos(m, d)                                 # cdof and subtree_com, used by mj_jacSite
            xyz_i[:] = ee
            jac_site(m, d, jac_i, None, site)             # writes the (3, nv = Dq) row block in place
        return xyz, jac


def camera_moves(model: mujoco.MjModel, camera: int) -> bool:
    """Whether the model's camera `camera` (id) moves with the arm: it rides on a body a joint moves, or tracks one."""
    return bool(model.body_weldid[model.cam_bodyid[camera]] != 0
                or model.cam_mode[camera] != mujoco.mjtCamLight.mjCAMLIGHT_FIXED)


def subtree(model: mujoco.MjModel, body: int) -> np.ndarray:
    """(nbody,) bool: `body` and every body below it (MuJoCo numbers a parent before its children)."""
    inside = np.zeros(model.nbody, dtype=bool)
    inside[body] = True
    for b in range(body + 1, model.nbody):
        inside[b] = inside[model.body_parentid[b]]
    return inside


def fixed_camera(model: mujoco.MjModel, data: mujoco.MjData, camera: int, image_size: tuple[int, int]) -> FixedCamera:
    """The model's camera `camera` (id) as a FixedCamera. Cameras are fixed in the world: its pose is computed once,
    at qpos0 (mj_camlight sets cam_xpos/xmat after mj_kinematics), with `data` (whose state it changes)."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    return FixedCamera.from_mujoco(data.cam_xpos[camera], data.cam_xmat[camera], model.cam_fovy[camera], image_size)
