"""The pinhole camera: the projection formula shared by the robot (to write `ee_pixel`) and the validator (to check
it), and a camera fixed in the world (`FixedCamera`: a robot's, posed once from its model). Numpy only: the
validator imports it without MuJoCo."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def project(K: np.ndarray, world_to_cam: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """(N, 3) m world -> (N, 2) px through K (3, 3) and a (4, 4) world->camera pose (OpenCV: z forward)."""
    cam = xyz @ world_to_cam[:3, :3].T + world_to_cam[:3, 3]  # (N, 3) camera frame, m
    uvw = cam @ K.T  # (N, 3)
    return uvw[:, :2] / uvw[:, 2:3]


OPENCV_FROM_MUJOCO_CAM = np.diag([1.0, -1.0, -1.0])   # MuJoCo camera: x right, y up, looks along −z


@dataclass(frozen=True, eq=False)
class FixedCamera:
    """A camera fixed in the world, for one image size: world → camera (OpenCV: x right, y down, z forward) and K."""

    rot: np.ndarray                # (3, 3) world → camera rotation
    trans: np.ndarray              # (3,) m, world → camera translation
    K: np.ndarray                  # (3, 3) px intrinsics, square pixels, principal point at the image centre
    image_size: tuple[int, int]    # (H, W) px

    @classmethod
    def from_mujoco(cls, xpos: np.ndarray, xmat: np.ndarray, fovy_deg: float,
                    image_size: tuple[int, int]) -> "FixedCamera":
        """From a MuJoCo camera's world pose (cam_xpos (3,) m, cam_xmat (9,)) and vertical field of view (deg)."""
        rot = OPENCV_FROM_MUJOCO_CAM @ xmat.reshape(3, 3).T
        h, w = image_size
        f = 0.5 * h / np.tan(0.5 * np.deg2rad(fovy_deg))   # px
        K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
        return cls(rot, -rot @ xpos, K, image_size)

    def extrinsics(self) -> np.ndarray:
        """(4, 4) world → camera."""
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = self.rot, self.trans
        return t

    def project(self, xyz: np.ndarray) -> np.ndarray:
        """(N, 3) m world → (N, 2) px (u = column, v = row)."""
        return project(self.K, self.extrinsics(), xyz)

    def sees(self, xyz: np.ndarray) -> np.ndarray:
        """(N, 3) m → (N,) bool: the point lies in front of the camera and projects inside the image."""
        depth = xyz @ self.rot[2] + self.trans[2]                        # (N,) m along the optical axis
        px = self.project(xyz)                                           # (N, 2) px
        h, w = self.image_size
        return (depth > 0) & (px >= 0).all(axis=1) & (px[:, 0] <= w - 1) & (px[:, 1] <= h - 1)

    def project_jacobian(self, xyz: np.ndarray) -> np.ndarray:
        """(N, 3) m → (N, 2, 3) d px / d m of `project`."""
        cam = xyz @ self.rot.T + self.trans                              # (N, 3)
        f = self.K[0, 0]
        inv_z = 1.0 / cam[:, 2:3]                                        # (N, 1)
        # d(X/Z)/dx = (R₀ − (X/Z) R₂) / Z, likewise for Y
        du = f * (self.rot[0][None] - cam[:, 0:1] * inv_z * self.rot[2][None]) * inv_z   # (N, 3)
        dv = f * (self.rot[1][None] - cam[:, 1:2] * inv_z * self.rot[2][None]) * inv_z
        return np.stack([du, dv], axis=1)

