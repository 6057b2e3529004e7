"""`bodyschema robot init FILE` and `bodyschema robot show FILE|NAME`: a robot record written, a robot looked at.

    bodyschema robot init arm.urdf --mesh-dir meshes/     writes arm.toml beside it with the inferred values
    bodyschema robot show arm.urdf                        joints, limits, sites, bodies, cameras, the record, the
                                                          fraction of poses whose ee is in view, how much the image
                                                          changes per degree of each joint, a contact sheet
    bodyschema robot camera arm.toml                      places the record's camera (and image size) anew for its
                                                          edited workspace, so that every joint is seen

The configs are light (the CLI imports them at start-up); the runners import MuJoCo when they run.
"""

from __future__ import annotations

import logging
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

from bodyschema.cli_marks import Positional
from bodyschema.errors import must_be

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RobotInitArgs:
    """Write the robot record of an MJCF/URDF file (values inferred from the file) for you to edit."""

    model: Annotated[Path, Positional("FILE")]   # the .xml or .urdf
    out: Path | None = None            # the record; None: <FILE stem>.toml beside the file (what --robot FILE reads)
    mesh_dir: Path | None = None       # URDF: where package:// meshes are, besides the file's folder and its parents
    # URDF: collision renders the collision geometry (e.g. .dae visuals); primitives draws capsules and boxes sized
    # from the links instead of any mesh (meshes missing, elsewhere or in a format MuJoCo does not load)
    visual: Literal["mesh", "collision", "primitives"] = "mesh"
    ee: str | None = None              # the end effector, a body or site; None: the hand ending the longest arm chain
    joints: tuple[str, ...] = ()       # the hinges used; (): the arm chain up to the ee (fingers, mimic joints out)
    image_size: tuple[int, int] = (64, 64)          # (H, W) px of the camera image
    overwrite: bool = False            # replace an existing record


@dataclass(frozen=True)
class RobotShowArgs:
    """Print a robot's joints, limits, sites, bodies, cameras and record, how often its camera sees the ee, how many
    pixels each joint changes per degree (a warning for a joint under the threshold), and write a contact sheet of
    rendered poses (PNG) with the ee pixel on each."""

    robot: Annotated[str, Positional("FILE|NAME")]   # shipped name or model file
    out: Path | None = None            # the PNG; None: <robot>_robot_sheet.png in the current folder
    n: int = 16                        # poses on the sheet (uniform in the camera workspace, seed 0)
    mesh_dir: Path | None = None       # URDF without a record: as `robot init --mesh-dir`
    visual: Literal["mesh", "collision", "primitives"] = "mesh"   # URDF without a record: as `robot init --visual`
    ee: str | None = None              # a file without a record: as `robot init --ee`
    joints: tuple[str, ...] = ()       # a file without a record: as `robot init --joints`


@dataclass(frozen=True)
class RobotCameraArgs:
    """Place a record's camera anew from sampled forward kinematics, framing the ee over one of its workspaces
    (after you narrowed it, or changed image_size): of several views and framings, the one that changes the largest
    share of its image for its weakest joints, and a larger image (up to --max-image-size) where that sees more joints
    (one whose share passes and pixel count does not: images under 64×64); joints still not seen are named with why;
    --add places a second view for those joints too. Rewrites the record in place (its leading comment kept, other
    comments not)."""

    record: Annotated[Path, Positional("RECORD")]   # a robot record (.toml)
    workspace: str = "camera"          # the joint box whose ee positions the camera frames
    max_image_size: int = 128          # px: the image's longer side may grow up to this (never shrinks)
    # also place a further camera (`cameras`: image_auto2) for the joints the first does not see; it may be a
    # close-up that loses the ee in some poses
    add: bool = False
    # also place cameras riding on links (`cameras`: image_mounted, image_mounted2, ..., as wrist cameras), each
    # looking at the bodies beyond its link: one per value, "auto" (the link under which the weakest joint is seen
    # best, given the cameras before it) or a joint's name (on its parent link); they replace the record's mounted
    # cameras
    mount: tuple[str, ...] = ()
    # the mounted cameras draw only their link and the bodies beyond it (the rest of the arm and the world left
    # out, as a segmentation of the hand gives): their images change with the joints beyond the link alone
    masked: bool = False


def run_init(args: RobotInitArgs) -> int:
    from bodyschema.datagen.body import formats
    from bodyschema.datagen.body.infer import infer_record
    from bodyschema.datagen.body.record import dumps_toml, write_record

    if args.model.suffix.lower() not in formats.suffixes() or not args.model.is_file():
        raise ValueError(must_be("FILE", f"an existing {formats.described()} file", str(args.model)))
    out = args.out or args.model.with_suffix(".toml")
    if out.exists() and not args.overwrite:
        raise FileExistsError(must_be("--out", "a new path", str(out), "Pass --overwrite to replace the record."))
    record = infer_record(args.model, args.mesh_dir, args.visual, args.image_size, args.ee, args.joints)
    if out.resolve().parent != record.base:                       # the record names the model relative to itself
        record = _rebased(record, out.resolve().parent)
    write_record(record, out, f"Robot record of {args.model.name}, written by `bodyschema robot init` with inferred "
                              f"values: edit them (see datagen/body/record.py).{_replaced_note(record)}")
    print(dumps_toml(record.to_toml_dict()))
    print(f"record: {out}")
    return 0


def run_camera(args: RobotCameraArgs) -> int:
    import dataclasses
    import itertools

    import numpy as np

    from bodyschema.datagen.body.camera_choice import FURTHER, choose_camera, choose_further_camera
    from bodyschema.datagen.body.camera_mount import AUTO_MOUNT, is_mounted, mount_camera, mounted_names
    from bodyschema.datagen.body.infer import check_view
    from bodyschema.datagen.body.observability import unseen_warnings
    from bodyschema.datagen.body.record import RECORD_SUFFIX, read_record, write_record
    from bodyschema.datagen.body.robot import Robot

    if args.record.suffix.lower() != RECORD_SUFFIX or not args.record.is_file():
        raise ValueError(must_be("RECORD", "an existing robot record (.toml)", str(args.record),
                                 "`bodyschema robot init FILE` writes one."))
    record = read_record(args.record)
    if args.workspace not in record.workspaces:
        raise ValueError(must_be("--workspace", f"one of the record's {sorted(record.workspaces)}", args.workspace))
    if not isinstance(args.max_image_size, int) or args.max_image_size < 1:
        raise ValueError(must_be("--max-image-size", "an integer >= 1 (px)", args.max_image_size))
    box = np.array(record.workspaces[args.workspace])
    if args.mount:                       # --mount sets the mounted cameras: none of an earlier, longer --mount stays
        record = dataclasses.replace(record, cameras=tuple(c for c, n in zip(record.cameras, record.further_cameras)
                                                           if not is_mounted(n)))
    names = mounted_names(len(args.mount))
    joints = {name: joint for name, joint in zip(names, args.mount) if joint != AUTO_MOUNT}
    on_links = {}
    if joints:                                           # a joint that cannot take one: refused before the search
        with Robot.load(record) as robot:
            on_links = {name: mount_camera(robot, joint, box, name, args.masked) for name, joint in joints.items()}
    choice = choose_camera(record, box, max(args.max_image_size, *record.image_size))
    placed = dataclasses.replace(record, camera=choice.camera, image_size=choice.image_size)
    further = choose_further_camera(placed, box, choice.seen) if args.add else None
    if further is not None:
        placed = _with_further(placed, further.camera)
    fixed = (choice.seen, *((further.seen,) if further else ()))
    mounted = []                                         # each `auto` places for what the cameras before left weakest
    for name in names:
        placed, seen = _with_mounted(placed, name, on_links.get(name), box, [*fixed, *mounted], args.masked)
        mounted.append(seen)
    with Robot.load(placed) as robot:
        fraction = check_view(robot, box)                    # refused before the record is touched
    lines = args.record.read_text().splitlines()
    header = list(itertools.takewhile(lambda line: line.startswith("#"), lines))   # the leading comment is kept
    write_record(placed, args.record, "\n".join(line.lstrip("#").removeprefix(" ") for line in header))
    print(f"before: {choice.before.table()}")
    print(f"after:  {choice.seen.table()}")
    print(f"camera {record.camera.get('pos')} → {choice.camera['pos']} (m), image {tuple(record.image_size)} → "
          f"{choice.image_size} px, the best of {choice.tried} views and framings of the ee over workspace "
          f"{args.workspace!r}: ee in view {fraction:.1%}")
    if further is not None:
        print(f"further camera {FURTHER!r} (image_{FURTHER}): {further.seen.table()}")
    links = {c["name"]: c["body"] for c in placed.cameras if isinstance(c, dict) and "body" in c}
    for seen in mounted:
        print(f"mounted camera {seen.camera!r} (image_{seen.camera}) on link {links[seen.camera]!r}: {seen.table()}")
    if further is not None and not mounted:
        print(f"joints seen by neither camera (< the threshold in both): {', '.join(further.unseen) or 'none'}")
    views = [*fixed, *mounted]                           # several: a warning per joint no camera sees
    for warning in unseen_warnings(views) if len(views) > 1 else choice.warnings():
        logger.warning(warning)
    print(f"record: {args.record}")
    return 0


def _with_mounted(record, name: str, camera: dict | None, box, views, masked: bool):
    """`record` with the mounted camera `name` (`camera`, or `choose_mount`'s over `views` when None), and its
    Observability."""
    import numpy as np

    from bodyschema.base.modalities import camera_modality
    from bodyschema.datagen.body.camera_mount import choose_mount
    from bodyschema.datagen.body.observability import observability
    from bodyschema.datagen.body.robot import Robot

    if camera is None:
        camera, seen = choose_mount(record, box, views, name, masked)
        return _with_further(record, camera), seen
    placed = _with_further(record, camera)
    with Robot.load(placed) as robot:
        return placed, observability(robot, box, np.random.default_rng(0), modality=camera_modality(name))


def _with_further(record, camera: dict):
    """`record` with the placed further camera `camera` in `cameras`, replacing one of its name."""
    import dataclasses
    kept = tuple(c for c, name in zip(record.cameras, record.further_cameras) if name != camera["name"])
    return dataclasses.replace(record, cameras=(*kept, camera))


def _replaced_note(record) -> str:
    """With visual = "primitives": which links are drawn as primitives, and the meshes they replace."""
    if record.visual != "primitives":
        return ""
    from bodyschema.datagen.body.build import read_source
    replaced = read_source(record)[1].replaced
    meshes = sorted({mesh for found in replaced.values() for mesh in found})
    return (f"\nvisual = \"primitives\": {len(replaced)} links drawn as capsules/boxes instead of {len(meshes)} "
            "meshes:\n" + "\n".join(f"  {link}: {', '.join(found)}" for link, found in replaced.items()))


def _rebased(record, folder: Path):
    import dataclasses
    import os
    model = os.path.relpath(record.model_path, folder)
    mesh = os.path.relpath(record.mesh_path, folder) if record.mesh_path else ""
    return dataclasses.replace(record, model=model, mesh_dir=mesh, base=folder)


def run_show(args: RobotShowArgs) -> int:
    from bodyschema.datagen.body.infer import check_view, infer_record
    from bodyschema.datagen.body.observability import every_camera, unseen_warnings
    from bodyschema.datagen.body.record import dumps_toml, load_record, robot_label
    from bodyschema.datagen.body.robot import Robot

    if not isinstance(args.n, int) or args.n < 1:
        raise ValueError(must_be("--n", "an integer >= 1", args.n))
    record = load_record(args.robot)
    note = ""
    if record is None:
        record = infer_record(Path(args.robot), args.mesh_dir, args.visual, ee=args.ee, joints=args.joints)
        note = f"  (inferred: no record beside the file; `bodyschema robot init {args.robot}` writes one)"
    with Robot.load(record) as robot:
        print(describe(robot))
        print(f"record{note}:\n{dumps_toml(record.to_toml_dict())}")
        fraction = check_view(robot, robot.sampling_ranges)
        print(f"ee in view: {fraction:.1%} of uniform poses in workspace {robot.workspace!r}")
        views = every_camera(robot, robot.sampling_ranges)   # its own camera, then the record's further ones
        for seen in views:
            print(seen.table())
        for warning in unseen_warnings(views):
            logger.warning(warning)
        out = args.out or Path(f"{robot_label(args.robot)}_robot_sheet.png")
        print(f"contact sheet: {robot_sheet(robot, out, args.n)}")
    return 0


def describe(robot) -> str:
    """Joints with limits (rad), sites, bodies and cameras of the robot's compiled model."""
    m = robot.model
    joints = [f"  {name}: [{lo:.4f}, {hi:.4f}] rad" for name, (lo, hi) in zip(robot.joint_names, robot.joint_limits)]
    names = {kind: [getattr(m, kind)(i).name for i in range(count)]
             for kind, count in (("site", m.nsite), ("body", m.nbody), ("camera", m.ncam))}
    return "\n".join([f"robot {robot.name}: {robot.source.path} (sha256 {robot.mjcf_sha256[:12]}…)",
                      f"joints ({robot.dq}, the ee {robot.ee_site!r}, camera {robot.camera_name!r}):", *joints,
                      *(f"{kind}s: {', '.join(n for n in found if n)}" for kind, found in names.items())])


def robot_sheet(robot, out: Path, n: int) -> Path:
    """A contact sheet (datagen/store/contact_sheet.py) of n rendered poses uniform in the sampling ranges (seed 0)."""
    import numpy as np
    import zarr

    from bodyschema.datagen.store.contact_sheet import write_contact_sheet

    ranges = robot.sampling_ranges
    q = np.random.default_rng(0).uniform(ranges[:, 0], ranges[:, 1], (n, robot.dq))
    observed = robot.observe(q)
    with tempfile.TemporaryDirectory(prefix="bodyschema-robot-sheet-") as tmp:
        root = zarr.open_group(Path(tmp) / "poses.zarr", mode="w")
        for key in ("image", "ee_pixel"):
            root.create_array(key, data=observed[key])
        return write_contact_sheet(Path(tmp) / "poses.zarr", out, n=n)
