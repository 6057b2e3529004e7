"""The checks of what a caller hands a `Robot`: its load arguments, joint boxes and points, as house errors.

(The batch of poses, `Robot.check_q`, stays on the robot: its tolerance is the robot's `LIMIT_TOLERANCE`.)
"""

from __future__ import annotations

import numpy as np

from bodyschema.errors import must_be

IMAGE_SIZE_RANGE = (8, 1024)   # px, per side; the MJCF offscreen buffers are 1024 × 1024


def check_ranges(ranges, joint_names: tuple[str, ...], joint_limits: np.ndarray, robot: str) -> None:
    """Raise the house ValueError unless `ranges` (Dq, 2) rad are ordered and inside the joint limits (Dq, 2) rad
    of the joints `joint_names` of `robot`."""
    dq = len(joint_names)
    try:
        r = np.asarray(ranges, dtype=np.float64)
    except (TypeError, ValueError):
        r = None
    if r is None or r.shape != (dq, 2) or not np.isfinite(r).all():
        raise ValueError(must_be("sampling ranges", f"a finite array of shape ({dq}, 2) in rad", ranges,
                                 f"One [low, high] per joint of {list(joint_names)}."))
    for j, (lo, hi) in enumerate(r):
        jlo, jhi = joint_limits[j]
        if not (jlo <= lo < hi <= jhi):
            raise ValueError(must_be(f"sampling range of {joint_names[j]}",
                                     f"ordered and inside the joint limits [{jlo:.4f}, {jhi:.4f}] rad",
                                     [float(lo), float(hi)], f"Fix the range in the record of {robot}."))


def checked_points(xyz) -> np.ndarray:
    """`xyz` as a float64 (N, 3) array in m; the house ValueError for another shape or a NaN/inf."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or not np.isfinite(xyz).all():
        raise ValueError(must_be("xyz", "a finite array of shape (N, 3) in m", xyz.shape))
    return xyz


def finite_float(x) -> float | None:
    """`x` as a finite float, else None (the caller names the argument)."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return None
    return x if np.isfinite(x) else None


def checked_image_size(size) -> tuple[int, int]:
    """(H, W) as ints, each side in IMAGE_SIZE_RANGE px; the house ValueError otherwise."""
    lo, hi = IMAGE_SIZE_RANGE
    try:
        h, w = (int(s) for s in size)
        ok = all(float(s) == int(s) for s in size) and lo <= h <= hi and lo <= w <= hi
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(must_be("image_size", f"(H, W) with each side an integer in [{lo}, {hi}] px", size))
    return h, w
