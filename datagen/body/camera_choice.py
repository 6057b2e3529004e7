"""`choose_camera`: the camera pose and image size of a record under which every chosen joint is seen, or the
joints that cannot be and why (`bodyschema robot camera`).

Candidates, each framing the ee over the workspace (`infer.place_camera`): the principal-axes view it always
placed, and views from AZIMUTHS around the ee's workspace at ELEVATIONS above it, each framing all the ee positions
or COVER_TIGHT of them (closer; the ee must stay in view in ≥ GOOD_VIEW of the poses). Each is scored by its
observability (`observability.py`, SEARCH_POSES poses at the record's image size): first how many joints pass
both of its thresholds (MIN_PX_PER_DEG pixels, MIN_SHARE_PER_DEG of the image), then Σ log min(%/°,
MIN_SHARE_PER_DEG) (a weak joint made less weak counts, a strong one made stronger does not). The best view then gets
the smallest image size, up to `max_side` px a side, that sees more joints; a size that does not is not taken (a
larger image keeps each joint's share of it, so it helps only where a joint's pixel count is short, and costs every
later render and model). Joints left under a threshold are named with why (`JointView.why`).
Cost: 1 + len(AZIMUTHS)·len(ELEVATIONS)·2 candidates × SEARCH_POSES·(1 + 2·Dq) renders, then a few sizes
(README's UR5, 5 joints, 64×64, 2 shared cores: ≈ 10 s).

`choose_further_camera` (`robot camera --add`) places a second view beside the first for the joints the first does
not see: of the same candidates at the chosen image size, and closer ones (framing FURTHER_COVERS of the ee
positions), the one whose per-joint best of the two views scores highest by the same rule; the record names it in
`cameras` (FURTHER), one more image modality. A second view need not keep the ee in view in GOOD_VIEW of the poses
(the first does): a close-up of the wrists that loses them in some poses is a candidate down to MIN_VIEW, the house
bound of any camera, and its px/° (a mean over poses, out-of-view ones counting 0) weighs what it sees against what
it loses. Cost: 1 + len(AZIMUTHS)·len(ELEVATIONS)·len(FURTHER_COVERS) = 49 candidates (the README's UR5 over `robot
init`'s ranges, 6 joints, 128×128: 64 s).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from bodyschema.datagen.body.infer import GOOD_VIEW, MIN_VIEW, ee_samples, place_camera, view_fraction
from bodyschema.datagen.body.observability import MIN_SHARE_PER_DEG, JointView, Observability, best_views, observability
from bodyschema.errors import must_be

AZIMUTHS = np.deg2rad(np.arange(0, 360, 60))   # views around the workspace's vertical axis (6)
ELEVATIONS = np.deg2rad([20.0, 55.0])           # above the horizontal: from the side, and from above
COVER_TIGHT = 0.95                              # a tighter framing: 95 % of the ee positions inside the margin
COVERS = (1.0, COVER_TIGHT)                     # the framings of a first camera (it must see the ee)
FURTHER_COVERS = (1.0, COVER_TIGHT, 0.75, 0.5)  # a second view's: close-ups too (the first sees the ee)
SEARCH_POSES = 8                                # poses per candidate while searching (the result is re-measured)
SCALES = (1.25, 1.5, 2.0, 3.0, 4.0)             # image sizes tried, × the record's, up to max_side
MAX_SIDE = 128                                  # px: the default bound on the image's longer side
FURTHER = "auto2"                               # the further camera `robot camera --add` places (image_auto2)


@dataclass(frozen=True)
class Choice:
    camera: dict                    # the record's [camera] values
    image_size: tuple[int, int]
    seen: Observability             # re-measured at POSES poses
    before: Observability           # the record's own camera, measured the same way
    tried: int                      # candidates scored

    max_side: int                   # px: the bound the image grew within

    def warnings(self) -> list[str]:
        """The house warning per joint still under the threshold: its figure, what was tried, and why."""
        tried = (f"Not seen at the best of {self.tried} views and framings, with images up to {self.max_side} px a "
                 "side")
        return [warning.replace("Not seen", tried, 1) for warning in self.seen.warnings()]


@dataclass(frozen=True)
class FurtherChoice:
    camera: dict                    # the entry of the record's `cameras`: {name, pos, xyaxes, fovy}
    seen: Observability             # its own view, measured at POSES poses
    unseen: tuple[str, ...]         # the joints neither view sees (weak in both: `JointView.weak`)


def _measure(record, box: np.ndarray, camera: dict, size: tuple[int, int], n: int,
             min_view: float = GOOD_VIEW) -> Observability | None:
    """The observability of `record` seen through `camera` at `size`; None where the ee is in view in fewer than
    min_view of the poses."""
    from bodyschema.datagen.body.robot import Robot
    placed = dataclasses.replace(record, camera=camera, image_size=size, cameras=())
    with Robot.load(placed) as robot:
        if view_fraction(robot, box) < min_view:
            return None
        return observability(robot, box, np.random.default_rng(0), n=n)


def _framings(covers: tuple[float, ...] = COVERS) -> list[dict]:
    """place_camera's keywords of every candidate: its own principal-axes view, then the views around and above,
    each framing each fraction `covers` of the ee positions."""
    return [{}] + [{"view": _direction(az, el), "cover": cover}
                   for az in AZIMUTHS for el in ELEVATIONS for cover in covers]


def _scored(record, box: np.ndarray, points: np.ndarray, size: tuple[int, int], what: str,
            covers: tuple[float, ...] = COVERS, min_view: float = GOOD_VIEW) -> list[tuple[dict, Observability]]:
    """(framing, its observability at SEARCH_POSES poses) of every candidate that keeps the ee in view in min_view
    of the poses; the house error naming `what` where none does."""
    framings = _framings(covers)
    scored = [(framing, seen) for framing in framings
              if (seen := _measure(record, box, place_camera(points, size, **framing), size, SEARCH_POSES,
                                   min_view)) is not None]
    if not scored:
        raise ValueError(must_be(f"{what} framing the ee of robot {record.name!r}",
                                 f"able to see it in at least {min_view:.0%} of the poses", "none of "
                                 f"{len(framings)} views and framings",
                                 "Narrow the workspace to where the arm works."))
    return scored


def choose_camera(record, box: np.ndarray, max_side: int = MAX_SIDE) -> Choice:
    """The camera (and image size) of `record` (a RobotRecord) that sees its chosen joints best over the joint box
    `box` (Dq, 2) rad; the image grows only up to `max_side` px a side, and only where it sees more joints."""
    from bodyschema.datagen.body.robot import Robot

    with Robot.load(record) as robot:
        points = ee_samples(robot, box)
        before = observability(robot, box, np.random.default_rng(0))
    size = tuple(record.image_size)
    scored = _scored(record, box, points, size, "a camera")
    framing, seen = max(scored, key=lambda pair: _score(pair[1]))
    for scale in SCALES:                       # the smallest larger image that sees more joints, if any does
        bigger = (round(record.image_size[0] * scale), round(record.image_size[1] * scale))
        if max(bigger) > max_side:
            break
        larger = _measure(record, box, place_camera(points, bigger, **framing), bigger, SEARCH_POSES)
        if larger is not None and _unseen_by_pixels(larger.joints) < _unseen_by_pixels(seen.joints):
            size, seen = bigger, larger
            if not _unseen_by_pixels(seen.joints):
                break
    camera = place_camera(points, size, **framing)
    return Choice(camera, size, _measure(record, box, camera, size, before.poses) or seen, before, len(scored),
                  max_side)


def choose_further_camera(record, box: np.ndarray, first: Observability) -> FurtherChoice:
    """A second placed view of `record` (its image size), beside its camera seen as `first` over `box` (Dq, 2) rad:
    the candidate whose per-joint best of the two views scores highest (`_score`'s rule on the pair)."""
    from bodyschema.datagen.body.robot import Robot
    with Robot.load(record) as robot:
        points = ee_samples(robot, box)
    size = tuple(record.image_size)
    framing, _ = max(_scored(record, box, points, size, "a further camera", FURTHER_COVERS, MIN_VIEW),
                     key=lambda pair: _pair_score(first, pair[1]))
    camera = {**place_camera(points, size, **framing), "name": FURTHER}
    seen = _measure(record, box, camera, size, first.poses, MIN_VIEW)
    return FurtherChoice(camera, seen, tuple(j.name for j in _best_of(first, seen) if j.weak))


def _unseen_by_pixels(joints: tuple[JointView, ...]) -> int:
    """The joints under either pixel threshold (a roll about the tool's axis is not seen in any view or size, and is
    left out). Only the count MIN_PX_PER_DEG grows with the image; where every joint's share passes
    MIN_SHARE_PER_DEG at 64×64 or more, so does its count, and the image keeps its size (SO-101: 80 000 poses at
    64×64 floored lower than 20 000 at 128×128, the same CPU time; README "The image's share of a joint")."""
    return sum((j.few_pixels or j.small_share) and not j.on_axis for j in joints)


def _best_of(first: Observability, second: Observability) -> tuple[JointView, ...]:
    """Per joint, its figures in the view that changes more of the image (both views are of one size)."""
    return tuple(view.joints[i] for i, view in enumerate(best_views((first, second))))


def _pair_score(first: Observability, second: Observability) -> tuple[int, float]:
    return _rank(_best_of(first, second))


def _direction(azimuth: float, elevation: float) -> np.ndarray:
    """(3,) unit vector from the workspace toward the camera."""
    return np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])


def _score(seen: Observability) -> tuple[int, float]:
    return _rank(seen.joints)


def _rank(joints: tuple[JointView, ...]) -> tuple[int, float]:
    """A view's rank from its joints' figures: first how many pass the pixel thresholds, then
    Σ log min(%/°, MIN_SHARE_PER_DEG)."""
    share = np.array([j.share_per_deg for j in joints])
    return -_unseen_by_pixels(joints), float(np.log(np.minimum(share, MIN_SHARE_PER_DEG) + 1e-4).sum())
