"""The rubber-hand scene: where the real hand rests and where the seen (fake) hand is shown.

Per episode the arm rests at a pose q* drawn from the models' joint box; the seen hand is the real hand moved by the
displacement d (m) in the camera's image plane, towards the image centre (as a fake hand laid beside the real one
on the table, in full view). A pose is kept only when the seen hand stays inside the image at the largest
displacement; when no pose of `TRIES` does, the displacement leaves the camera view: the house error.
Every episode draws from its own generator (`SeedSequence([EVAL_STREAM, STREAM_WORD, seed, episode, role])`), so
its pose, strokes and noise are the same in every condition (common random numbers across the sweep).
"""

from __future__ import annotations

import numpy as np

from bodyschema.errors import must_be
from bodyschema.evaluation.core.seeds import EVAL_STREAM

STREAM_WORD = 0x2B8E                    # second entropy word: rubber-hand episodes
ROLE = {"pose": 0, "strokes": 1, "proprio_noise": 2, "visual_noise": 3}
TRIES = 200                             # poses tried per episode for one whose seen hand stays in view


def episode_rng(seed: int, episode: int, role: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([EVAL_STREAM, STREAM_WORD, int(seed), int(episode),
                                                         ROLE[role]]))


def camera_frame(robot, xyz: np.ndarray) -> np.ndarray:
    """(N, 3) m world → camera frame (x right, y down, z forward), m."""
    ext = robot.extrinsics()
    return xyz @ ext[:3, :3].T + ext[:3, 3]


def in_view(robot, xyz: np.ndarray) -> np.ndarray:
    """(N, 3) m → (N,) bool: in front of the camera and projected inside the image."""
    depth = camera_frame(robot, xyz)[:, 2]
    px = robot.project(xyz)
    h, w = robot.image_size
    return (depth > 0) & (px >= 0).all(axis=1) & (px[:, 0] <= w - 1) & (px[:, 1] <= h - 1)


def towards_centre(robot, xyz: np.ndarray) -> np.ndarray:
    """(N, 3) unit world directions in the image plane from each point towards the optical axis."""
    cam = camera_frame(robot, xyz)
    planar = -cam[:, :2]                                                 # (N, 2) towards the axis
    norm = np.linalg.norm(planar, axis=1, keepdims=True)
    planar = np.where(norm > 1e-9, planar / np.maximum(norm, 1e-12), np.array([1.0, 0.0]))
    rot = robot.extrinsics()[:3, :3]                                     # world → camera
    return np.c_[planar, np.zeros(len(planar))] @ rot                   # (N, 3) back to the world


def rest_poses(robot, n: int, seed: int, max_displacement: float) -> tuple[np.ndarray, np.ndarray]:
    """(q* (N, Dq) rad, directions (N, 3)): per episode a resting pose whose seen hand stays in view at
    `max_displacement` m, and the displacement direction; the house error when an episode finds none."""
    low, high = robot.sampling_ranges.T
    poses, dirs = np.empty((n, robot.dq)), np.empty((n, 3))
    for i in range(n):
        q = episode_rng(seed, i, "pose").uniform(low, high, (TRIES, robot.dq))     # (TRIES, Dq) rad
        xyz = robot.fk(q, check=False)
        d = towards_centre(robot, xyz)
        ok = np.flatnonzero(in_view(robot, xyz) & in_view(robot, xyz + max_displacement * d))
        if ok.size == 0:
            raise ValueError(must_be("displacements", f"inside the camera view of {robot.name} "
                                     f"({robot.image_size[1]}×{robot.image_size[0]} px)", f"{max_displacement} m",
                                     f"No pose of {TRIES} keeps a hand moved that far in the image: use smaller "
                                     "displacements or a robot whose camera sees more (planar2, panda)."))
        poses[i], dirs[i] = q[ok[0]], d[ok[0]]
    return poses, dirs
