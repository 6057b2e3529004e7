"""The body of an imported store: joint names, limits and the joint box, from a shipped robot, from `--joints`
(limits: `--ranges`, else the box of the recorded joint values), or from the attrs a bodyschema export carries; and
the recorded angles mapped onto it (order, unit, limits). A named CSV/state column the body does not have, a joint
the recording lacks, NaN, a unit left unstated or an angle outside the limits is the house error before anything is
written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.recording import Recording, check_finite
from bodyschema.datagen.store.reader import attrs_body
from bodyschema.errors import must_be

RANGE_TOL = 1e-5   # rad: float32 rounding of the range ends (as validate_store)
ROBOT_ATTRS = ("mjcf_sha256", "camera_name", "intrinsics", "extrinsics", "reach_m", "base_m")
SELF_CONTAINED = ("robot_record", "robot_model")   # datagen/body/attrs.py: the record and the model text


@dataclass
class Body:
    name: str
    joint_names: tuple[str, ...]
    joint_limits: np.ndarray                  # (Dq, 2) rad
    ranges: np.ndarray | None                 # (Dq, 2) rad: the joint box models scale by (None: the recording's)
    attrs: dict[str, Any] = field(default_factory=dict)   # ROBOT_ATTRS (None where unknown)
    robot: Any = None                         # a datagen Robot (for --fk), else None


def resolve_body(config: ImportConfig, rec: Recording, image_size: tuple[int, int] | None) -> Body:
    """The body the store is of; image_size (H, W) px sets a robot camera's intrinsics to the imported images."""
    if config.robot is not None:
        body = _robot_body(config.robot, image_size)
    elif config.joints is not None:
        body = Body(config.name, tuple(config.joints), np.empty((len(config.joints), 2)), None,
                    dict.fromkeys(ROBOT_ATTRS))
        body.joint_limits = (np.asarray(config.ranges, float) * _factor(config, rec) if config.ranges is not None
                             else data_box(rec, body) * _factor(config, rec))
    elif rec.attrs:
        a, spec = rec.attrs, attrs_body(rec.attrs, rec.q.shape[1])       # the body the export's models scale by
        body = Body(spec["robot"], tuple(spec["joint_names"]), np.asarray(a["joint_limits"], float),
                    np.array([spec["q_low"], spec["q_high"]]).T,
                    {**{k: a.get(k) for k in ROBOT_ATTRS}, **{k: a[k] for k in SELF_CONTAINED if k in a}})
    else:
        raise ValueError(must_be("the body", "--robot NAME, or --joints NAMES (with --ranges, or the data's box)",
                                 "neither",
                                 "Only a bodyschema export records its body."))
    if config.ranges is not None:
        body.ranges = _checked_ranges(np.asarray(config.ranges, float) * _factor(config, rec), body)
    return body


def _robot_body(name: str, image_size: tuple[int, int] | None) -> Body:
    from bodyschema.datagen.body.attrs import camera_attrs, robot_attrs
    from bodyschema.datagen.body.reach import arm_reach
    from bodyschema.datagen.body.robot import Robot

    robot = Robot.load(name, image_size=image_size)
    base, reach = arm_reach(robot.model, robot.ee_site)
    attrs = {"mjcf_sha256": robot.mjcf_sha256, **camera_attrs(robot), "reach_m": reach, "base_m": base.tolist(),
             **robot_attrs(robot)}   # the store rebuilds its robot
    return Body(robot.name, tuple(robot.joint_names), robot.joint_limits.copy(), None, attrs, robot)


def _checked_ranges(ranges: np.ndarray, body: Body) -> np.ndarray:
    dq = len(body.joint_names)
    if ranges.shape != (dq, 2):
        raise ValueError(must_be("--ranges", f"one (lo, hi) per joint of {list(body.joint_names)}",
                                 f"{len(ranges)} pairs"))
    lo, hi = body.joint_limits.T
    outside = (ranges[:, 0] < lo - RANGE_TOL) | (ranges[:, 1] > hi + RANGE_TOL)
    if outside.any():
        j = int(np.argmax(outside))
        raise ValueError(must_be(f"--ranges of {body.joint_names[j]}", f"inside the joint limits "
                                 f"{body.joint_limits[j].round(4).tolist()} rad", ranges[j].round(4).tolist()))
    return ranges


def _factor(config: ImportConfig, rec: Recording) -> float:
    """rad per recorded unit: the source's stated unit, or --angles (required when the source states none)."""
    if rec.unit == "rad":
        if config.angles == "deg":
            raise ValueError(must_be("--angles", "rad (or left out) for this source", "deg",
                                     "It records its angles in rad."))
        return 1.0
    if config.angles is None:
        raise ValueError(must_be("--angles", "deg or rad", None,
                                 "This source does not state the unit of its joint angles; say which it is."))
    return config.to_rad


def joint_angles(config: ImportConfig, rec: Recording, body: Body) -> np.ndarray:
    """(N, Dq) float64 rad in the body's joint order, finite and inside the limits and the joint box."""
    check_finite("joint angles", rec.q, rec.image_names or None)
    q = _in_body_order(rec, body) * _factor(config, rec)
    unit = "deg" if config.angles == "deg" else "rad"
    # An export's joint box is where targets were drawn; a babbling arm overshoots it, so only --ranges bound q.
    for box, what in ((body.joint_limits, "the joint limits"), (body.ranges, "--ranges")):
        if box is None or (what == "--ranges" and config.ranges is None):
            continue
        outside = (q < box[:, 0] - RANGE_TOL) | (q > box[:, 1] + RANGE_TOL)
        if outside.any():
            row, j = (int(i[0]) for i in np.nonzero(outside))
            where = rec.image_names[row] if rec.image_names else f"row {row}"
            raise ValueError(must_be(f"joint {body.joint_names[j]} at {where}",
                                     f"inside {what} {box[j].round(4).tolist()} rad",
                                     f"{q[row, j]:.4f} rad ({int(outside.any(axis=1).sum())} rows outside)",
                                     f"Check --angles (read as {unit}) and which column is which joint."))
    return q


def data_box(rec: Recording, body: Body) -> np.ndarray:
    """(Dq, 2) in the recorded unit: the box of every joint value recorded (the angles and, where kept, the commanded
    targets): the joint limits of a --joints body without --ranges."""
    recorded = [in_body_order(rec, body, rec.q)]
    if "target" in rec.arrays:
        recorded.append(in_body_order(rec, body, np.asarray(rec.arrays["target"], float)))
    values = np.concatenate(recorded)
    return np.stack([values.min(axis=0), values.max(axis=0)], axis=1)


def _in_body_order(rec: Recording, body: Body) -> np.ndarray:
    return in_body_order(rec, body, rec.q)


def in_body_order(rec: Recording, body: Body, values: np.ndarray) -> np.ndarray:
    """`values` (N, K) with q's columns (rec.columns) → (N, Dq) in the body's joint order."""
    names, dq = list(body.joint_names), len(body.joint_names)
    if rec.columns is None:
        if values.shape[1] != dq:
            raise ValueError(must_be("joint-angle columns", f"{dq}, one per joint of {names}", values.shape[1],
                                     "Name the columns in a header row to pick and order them."))
        return values
    unknown = [c for c in rec.columns if c not in names]
    if unknown:
        raise ValueError(must_be(f"joint keys {unknown}", f"joints of the body {body.name!r}: {names}",
                                 list(rec.columns), "Rename or drop those columns (or pick the body with "
                                 "--robot / --joints)."))
    missing = [n for n in names if n not in rec.columns]
    if missing:
        raise ValueError(must_be(f"joints {missing}", "recorded", f"columns {list(rec.columns)}"))
    return values[:, [rec.columns.index(n) for n in names]]


def joint_box(q: np.ndarray, body: Body) -> np.ndarray:
    """(Dq, 2) rad: the given joint box, else the one the recording covers (a model's latent scaling)."""
    if body.ranges is not None:
        return body.ranges
    box = np.stack([q.min(axis=0), q.max(axis=0)], axis=1)
    still = np.flatnonzero(box[:, 1] <= box[:, 0])
    if still.size:
        raise ValueError(must_be(f"joint {body.joint_names[still[0]]}", "moving in the recording (its range is "
                                 "the model's scaling)", f"constant at {box[still[0], 0]:.4f} rad",
                                 "Pass --ranges, or record it moving."))
    return box
