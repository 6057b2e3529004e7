"""Pinhole projection, the one formula shared by the robot (to write `ee_pixel`) and the validator (to check it)."""

from __future__ import annotations

import numpy as np


def project(K: np.ndarray, world_to_cam: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """(N, 3) m world -> (N, 2) px through K (3, 3) and a (4, 4) world->camera pose (OpenCV: z forward)."""
    cam = xyz @ world_to_cam[:3, :3].T + world_to_cam[:3, 3]  # (N, 3) camera frame, m
    uvw = cam @ K.T  # (N, 3)
    return uvw[:, :2] / uvw[:, 2:3]
