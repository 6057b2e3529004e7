"""The physical checks of a store's rows, one chunk of rows at a time, and the house line of each failing check.

Per chunk, `check_rows` counts into a `RowTally` the rows that are not finite, or not physical: q outside the
recorded ranges or the joint limits, ee_xyz beyond the arm's reach of its base, a Jacobian column longer than the
reach (m/rad), ee_pixel off ee_xyz projected through the stored camera, negative touch, t or episode, |qvel| above
MAX_JOINT_SPEED, babbling targets outside the joint limits. After the last chunk, `report_rows` writes one line per
check with its row count, first row and worst value (`validate_store` gathers them with its other problems).
"""

from __future__ import annotations

import numpy as np

from bodyschema.datagen.body.camera import project
from bodyschema.datagen.store.remedies import EDITED_HINT, REGENERATE_HINT, RESUME_HINT
from bodyschema.datagen.store.schema import MAX_JOINT_SPEED
from bodyschema.errors import must_be

PIXEL_TOL = 0.05  # px; float32 storage of ee_xyz/ee_pixel gives ~1e-4 px, a real shift is >= 0.1 px
RANGE_TOL = 1e-5  # rad; float32 rounding of the range ends
REACH_TOL = 1e-4  # m (and m/rad); float32 rounding is ~1e-7 m, while the reach bound is reached only at full stretch


class RowTally:
    """Rows failing one check: count, first row and worst value, summed over the chunks of rows."""

    def __init__(self) -> None:
        self.rows: dict[str, list] = {}

    def add(self, key: str, bad: np.ndarray, start: int, worst: np.ndarray | None = None) -> None:
        if not bad.any():
            return
        entry = self.rows.setdefault(key, [0, start + int(np.argmax(bad)), 0.0])
        entry[0] += int(bad.sum())
        if worst is not None:
            entry[2] = max(entry[2], float(np.max(worst[bad])))


def check_rows(block: dict[str, np.ndarray], attrs: dict, limits: np.ndarray | None, start: int,
                  tally: RowTally) -> None:
    """Finiteness and physical range of one chunk of rows; NaN/inf rows are counted once, as not finite."""
    finite = {}
    for name, values in block.items():
        if values.dtype.kind == "f":
            finite[name] = np.isfinite(values.reshape(len(values), -1)).all(axis=1)
            tally.add(f"finite:{name}", ~finite[name], start)
    ok = {name: finite.get(name, np.ones(len(v), bool)) for name, v in block.items()}
    if "episode" in block:
        tally.add("episode", block["episode"] < 0, start)
    for name in ("touch", "t"):
        if name in block:
            tally.add(f"nonneg:{name}", (block[name].reshape(len(block[name]), -1) < 0).any(axis=1) & ok[name], start)
    q_range = _q_range(attrs)
    if "q" in block and q_range is not None and q_range.shape == (block["q"].shape[1], 2):
        tally.add("q", _outside(block["q"], q_range) & ok["q"], start)
    if ("q" in block and limits is not None and limits.shape == (block["q"].shape[1], 2)
            and not (q_range is not None and np.array_equal(q_range, limits))):  # the same box: reported once
        tally.add("limits:q", _outside(block["q"], limits) & ok["q"], start)
    if "target" in block and limits is not None and limits.shape == (block["target"].shape[1], 2):
        tally.add("limits:target", _outside(block["target"], limits) & ok["target"], start)
    if "qvel" in block:
        with np.errstate(invalid="ignore"):
            speed = np.abs(block["qvel"].astype(float)).max(axis=1)  # (B,) rad/s
        tally.add("speed:qvel", ~(speed <= MAX_JOINT_SPEED) & ok["qvel"], start, speed)
    reach, base = attrs.get("reach_m"), attrs.get("base_m")
    if reach is not None and base is not None:
        if "ee_xyz" in block:
            dist = np.linalg.norm(block["ee_xyz"].astype(float) - np.asarray(base, float), axis=1)  # (B,) m
            tally.add("reach:ee_xyz", ~(dist <= reach + REACH_TOL) & ok["ee_xyz"], start, dist)
        if "jacobian" in block:
            with np.errstate(over="ignore", invalid="ignore"):
                norms = np.linalg.norm(block["jacobian"].astype(float), axis=1).max(axis=1)  # (B,) m/rad
            tally.add("reach:jacobian", ~(norms <= reach + REACH_TOL) & ok["jacobian"], start, norms)
    for name, (K, E) in _views(attrs).items():
        if "ee_xyz" in block and name in block and K is not None and E is not None:
            with np.errstate(all="ignore"):
                err = np.abs(project(np.asarray(K, float), np.asarray(E, float), block["ee_xyz"].astype(float))
                             - block[name]).max(axis=1)
            tally.add(f"pixel:{name}", ~(err <= PIXEL_TOL) & ok["ee_xyz"] & ok[name], start, np.nan_to_num(err))


def _views(attrs: dict) -> dict[str, tuple]:
    """{ee projection array: (K, E) of its camera}: ee_pixel's from the attrs' intrinsics/extrinsics, each further
    camera's from camera_views (absent in stores made before further cameras had projections)."""
    views = attrs.get("camera_views")
    further = {name: (v.get("intrinsics"), v.get("extrinsics")) for name, v in views.items()
               if isinstance(v, dict)} if isinstance(views, dict) else {}
    return {"ee_pixel": (attrs.get("intrinsics"), attrs.get("extrinsics")), **further}


def _outside(q: np.ndarray, box: np.ndarray) -> np.ndarray:
    """(B,) rows of q (B, Dq) with a joint outside box (Dq, 2) by more than RANGE_TOL."""
    return ((q < box[:, 0] - RANGE_TOL) | (q > box[:, 1] + RANGE_TOL)).any(axis=1)


def _q_range(attrs: dict) -> np.ndarray | None:
    key = "sampling_ranges" if attrs.get("sampler") in ("uniform", "gaussian") else "joint_limits"
    try:
        return np.asarray(attrs[key], float) if key in attrs else None
    except (TypeError, ValueError):  # not numbers: reported by validate's attrs checks
        return None


def report_rows(tally: RowTally, attrs: dict, problems: list[str]) -> None:
    ranges_key = "sampling_ranges" if attrs.get("sampler") in ("uniform", "gaussian") else "joint_limits"
    reach, base = attrs.get("reach_m"), attrs.get("base_m")
    for key, (count, row, worst) in tally.rows.items():
        kind, _, name = key.partition(":")
        where = f"{count} rows, first at row {row}"
        if kind == "finite":
            problems.append(must_be(name, "finite", f"{count} rows with NaN/inf, first at row {row}",
                                    "NaN marks samples never written: " + RESUME_HINT))
        elif kind == "episode":
            problems.append(must_be("episode", ">= 0", f"negative values, first at row {row}", RESUME_HINT))
        elif kind == "nonneg":
            problems.append(must_be(name, ">= 0", f"negative values in {where}", REGENERATE_HINT))
        elif kind == "q":
            problems.append(must_be("q", f"inside the recorded {ranges_key} (+-{RANGE_TOL} rad)",
                                    f"{count} rows outside, first at row {row}"))
        elif key == "limits:q":
            problems.append(must_be("q", f"inside the {attrs.get('robot')} joint limits (+-{RANGE_TOL} rad)",
                                    f"{count} rows outside, first at row {row}", EDITED_HINT))
        elif key == "limits:target":
            problems.append(must_be("target", f"inside the {attrs.get('robot')} joint limits (+-{RANGE_TOL} rad): "
                                    "servo targets a babbling robot can be given", f"{where} outside",
                                    REGENERATE_HINT))
        elif key == "speed:qvel":
            problems.append(must_be("qvel", f"|qvel| <= {MAX_JOINT_SPEED:g} rad/s (a stable simulation)",
                                    f"{where}, up to {worst:.4g} rad/s", REGENERATE_HINT))
        elif key == "reach:ee_xyz":
            problems.append(must_be("ee_xyz", f"within the arm's reach, {reach:.4f} m of its base {base} m",
                                    f"{where}, up to {worst:.4g} m away", REGENERATE_HINT))
        elif key == "reach:jacobian":
            problems.append(must_be("jacobian", f"columns of norm <= the arm's reach {reach:.4f} m/rad",
                                    f"{where}, up to {worst:.4g} m/rad", REGENERATE_HINT))
        elif kind == "pixel":
            source = "intrinsics/extrinsics" if name == "ee_pixel" else f"camera_views[{name!r}]"
            problems.append(must_be(name, f"ee_xyz projected through attrs {source} (+-{PIXEL_TOL} px)",
                                    f"{count} rows off by up to {worst:.3g} px, first at row {row}"))
