"""Goal poses the robot camera sees: what a reaching episode (the benchmark's, the env's) reaches for."""

from __future__ import annotations

import numpy as np

from bodyschema.datagen.samplers import uniform


def in_view_targets(rng: np.random.Generator, robot, n: int, ranges=None) -> np.ndarray:
    """n uniform poses of the sampling ranges (or `ranges`) whose ee the camera sees (a goal pixel must be in the
    image; nao_arm's camera workspace keeps it in view for ~90 % of its poses); the first n draws when all are seen.
    Too few seen: the first n, and check_goal names a pose the camera cannot see. # (n, Dq) rad"""
    q = uniform(rng, robot.sampling_ranges if ranges is None else ranges, 20 * n)   # (20n, Dq)
    seen = q[robot.in_view(q)]
    return seen[:n] if len(seen) >= n else q[:n]
