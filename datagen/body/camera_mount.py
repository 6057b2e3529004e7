"""`mount_camera`: a further camera riding on a link, looking at the bodies beyond it (`robot camera --mount`).

A camera fixed in the world sees a wrist joint through a hand that covers a few per cent of its image; a camera on
the forearm sees the hand from the same place in every pose, large, and its image depends on the joints beyond the
link (and what of the rest of the arm comes into view behind them), as the wrist cameras of LeRobot's arms. It goes
on the parent link of a joint (`--mount JOINT`, or the one `choose_mount` picks), framing what that joint and those
after it move: the ee and the centres of the geoms beyond the link, over POSES poses of the workspace, in the link's
frame (`infer.place_camera`: along their direction of least spread, every point inside the frame's margin). The
record names it in `cameras` with `body` (MOUNTED: image_mounted, then image_mounted2, ... for more than one; no
ee_pixel_mounted: a camera that moves has no fixed projection). `masked` (`--masked`): it draws only its link and
the bodies beyond (render_scope), so its decoder learns the joints beyond the link without the background the joints
before it swing; cameras on several links of the arm (a cascade) then each see their joints from nearby.
"""

from __future__ import annotations

import dataclasses
import re

import mujoco
import numpy as np

from bodyschema.base.modalities import camera_modality
from bodyschema.datagen.body.infer import place_camera
from bodyschema.datagen.body.kinematics import subtree
from bodyschema.datagen.body.observability import best_views, observability
from bodyschema.errors import must_be

MOUNTED = "mounted"              # the further camera `robot camera --mount` places (image_mounted)
AUTO_MOUNT = "auto"              # `--mount auto`: the link `choose_mount` picks
POSES = 256                      # workspace poses whose ee and geoms the mounted camera frames


def mounted_names(n: int) -> tuple[str, ...]:
    """The names of n cameras `robot camera --mount` places: mounted, mounted2, mounted3, ..."""
    return tuple(MOUNTED if i == 0 else f"{MOUNTED}{i + 1}" for i in range(n))


def is_mounted(name: str) -> bool:
    """Whether a further camera's name is one `robot camera --mount` places (mounted_names)."""
    return re.fullmatch(rf"{MOUNTED}(\d+)?", name) is not None


def mount_camera(robot, joint: str, box: np.ndarray, name: str = MOUNTED, masked: bool = False) -> dict:
    """The record's `cameras` entry (`name`) of a camera on the parent link of `joint` (a chosen joint of `robot`, a
    datagen Robot), framing the ee and the geoms beyond that link over `box` (Dq, 2) rad (POSES poses, seed 0);
    `masked`: it draws only that link and the bodies beyond (render_scope)."""
    model = robot.model
    if joint not in robot.joint_names:
        raise ValueError(must_be("joint to mount a camera for", f"one of {robot.name}'s joints {robot.joint_names}",
                                 joint))
    moved = int(model.jnt_bodyid[model.joint(joint).id])
    link = int(model.body_parentid[moved])
    if not _on_moving_link(model, joint):
        raise ValueError(must_be(f"joint {joint!r} of {robot.name}", "a joint after the first moving link, to "
                                 "mount a camera before it", "a joint on a link fixed in the world",
                                 "A camera fixed in the world sees it: `robot camera` places one."))
    points = _points_beyond(model, link, moved, robot.ee_site, box, np.random.default_rng(0))
    camera = place_camera(points, robot.image_size)
    return {**camera, "name": name, "body": model.body(link).name, **({"masked": True} if masked else {})}


def choose_mount(record, box: np.ndarray, views, name: str = MOUNTED, masked: bool = False):
    """`--mount auto`: of a camera on the parent link of each joint after the first moving link (`mount_camera`),
    the one under which the arm's weakest joint is seen best, with its Observability. `views`: the Observability of
    the cameras the record has (fixed, and mounted ones placed before). A joint beyond the link counts its best share
    through the new camera or those views, as perception sums the cameras; a joint before it counts its best share in
    `views` alone: through a masked camera it is not seen, and through an unmasked one it moves the whole background,
    which a decoder did not learn (SO-101's wrist_flex: floor 12° seen so, 0.5° from the link before it). So a second
    `auto` after a first places for the joints the first left weakest. Rolls about the tool's own axis
    (`JointView.on_axis`) do not count: no camera sees them reliably. Returns the record's `cameras` entry, named
    `name` (`masked`: see mount_camera), and its Observability."""
    from bodyschema.datagen.body.robot import Robot
    before = [view.joints[i].share_per_deg for i, view in enumerate(best_views(views))]
    scored = []
    with Robot.load(record) as robot:
        names = robot.joint_names
        candidates = [(j, mount_camera(robot, j, box, name, masked)) for j in names
                      if _on_moving_link(robot.model, j)]
    if not candidates:
        raise ValueError(must_be(f"robot {record.name}", "an arm with a joint after its first moving link, to mount "
                                 "a camera on that link", f"joints {names}, each on a link fixed in the world",
                                 "A camera fixed in the world sees them: leave out --mount."))
    others = tuple(c for c, n in zip(record.cameras, record.further_cameras) if n != name)   # one of its name: replaced
    for joint, camera in candidates:
        with Robot.load(dataclasses.replace(record, cameras=(*others, camera))) as robot:
            seen = observability(robot, box, np.random.default_rng(0), modality=camera_modality(name))
        beyond = names.index(joint)
        shares = [max(seen.joints[i].share_per_deg, before[i]) if i >= beyond else before[i]
                  for i, j in enumerate(seen.joints) if not j.on_axis]
        scored.append((min(shares, default=0.0), camera, seen))
    _, camera, seen = max(scored, key=lambda s: s[0])
    return camera, seen


def _on_moving_link(model: mujoco.MjModel, joint: str) -> bool:
    """Whether `joint`'s parent link moves (a camera on it is not one fixed in the world)."""
    return bool(model.body_weldid[model.body_parentid[model.jnt_bodyid[model.joint(joint).id]]] != 0)


def _points_beyond(model: mujoco.MjModel, link: int, moved: int, site: str, box: np.ndarray,
                   rng: np.random.Generator) -> np.ndarray:
    """(POSES·(1 + G), 3) m in `link`'s frame: the ee and the centres of the G geoms on `moved` and the bodies below
    it, at POSES poses uniform in `box`."""
    geoms = np.flatnonzero(subtree(model, moved)[model.geom_bodyid])
    ee = model.site(site).id
    data = mujoco.MjData(model)
    out = []
    for q in rng.uniform(box[:, 0], box[:, 1], size=(POSES, len(box))):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        world = np.concatenate([data.site_xpos[ee][None], data.geom_xpos[geoms]])
        out.append((world - data.xpos[link]) @ data.xmat[link].reshape(3, 3))    # rows: points in the link's frame
    return np.concatenate(out)
