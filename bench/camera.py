"""Benchmark: how well nao_arm's camera sees the arm — the former wide "eye" vs CameraBottom, in the same run.

    .venv/bin/python bench/camera.py [--n 2000] [--sheet /work/briefs/camera_sheet.png]

On n uniform poses of the "camera" workspace, 56 x 80 grayscale, per camera:
  - arm coverage: mean fraction of image pixels that differ from the empty scene (the arm hidden), checked
    against an exact segmentation render on the first poses;
  - ee in view: fraction of poses whose projected ee (marker centre) lies inside the image;
  - image sensitivity: mean |Δ image| (grey levels per pixel) for a +1° step of each joint. This is what makes
    pixel perception precise: a decoder can only localise the arm to the extent a small joint error changes
    the picture;
and the ratio new / old. --sheet also writes a contact sheet of 16 random workspace poses (CameraBottom) made by
the real pipeline (generate + write_contact_sheet) to look at. Target: < 1 min (2 renders per pose and camera).
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from pathlib import Path

from bodyschema.datagen.body.robot import Robot  # first: bodyschema sets MUJOCO_GL before mujoco is imported

# isort: split
import cv2
import mujoco
import numpy as np

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.contact_sheet import write_contact_sheet

ROBOT, WORKSPACE = "nao_arm", "camera"
CAMERAS = {"old": "eye", "new": "CameraBottom"}
ARM_BODIES = ("LShoulder", "LBicep", "LElbow", "LForeArm")   # every geom of these bodies is the arm
STEP_RAD = np.deg2rad(1.0)
COVER_GREY = 16      # grey levels: a pixel differing this much from the empty scene shows the arm (≥ ~half covered)
N_CHECK = 200        # poses whose coverage is also measured exactly, by segmentation (slower), as a check


def background(robot: Robot) -> np.ndarray:
    """(H, W) uint8: the scene without the arm (its geoms moved to group 3, which MuJoCo hides by default)."""
    m = copy.copy(robot.model)                                               # the robot's model stays intact
    m.geom_group[arm_geoms(m)] = 3
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_camlight(m, d)
    h, w = robot.image_size
    with mujoco.Renderer(m, height=h, width=w) as renderer:
        renderer.update_scene(d, robot.camera_name)
        return cv2.cvtColor(renderer.render(), cv2.COLOR_RGB2GRAY)


def arm_geoms(m: mujoco.MjModel) -> np.ndarray:
    return np.flatnonzero(np.isin(m.geom_bodyid, [m.body(b).id for b in ARM_BODIES]))


def arm_coverage(images: np.ndarray, empty: np.ndarray) -> np.ndarray:
    """(N,) fraction of pixels that differ from the empty scene by > COVER_GREY (no shadows: only the arm does)."""
    diff = np.abs(images.astype(np.int16) - empty.astype(np.int16))          # (N, H, W)
    return (diff > COVER_GREY).mean(axis=(1, 2))


def segmented_coverage(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(N,) fraction of pixels whose front-most geom is the arm (segmentation render): checks `arm_coverage`."""
    m, d, arm = robot.model, mujoco.MjData(robot.model), arm_geoms(robot.model)
    h, w = robot.image_size
    out = np.empty(len(q))
    with mujoco.Renderer(m, height=h, width=w) as renderer:
        renderer.enable_segmentation_rendering()
        for i, q_i in enumerate(q):
            d.qpos[:] = q_i
            mujoco.mj_kinematics(m, d)
            mujoco.mj_camlight(m, d)
            renderer.update_scene(d, robot.camera_name)
            seg = renderer.render()                                          # (H, W, 2): object id, type
            out[i] = ((seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & np.isin(seg[..., 0], arm)).mean()
    return out


def ee_in_view(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(N,) bool: the projected ee lies inside the image (pixel centres 0 .. W-1, 0 .. H-1)."""
    px = robot.project(robot.fk(q))                                          # (N, 2) px
    h, w = robot.image_size
    return (px >= 0).all(axis=1) & (px[:, 0] <= w - 1) & (px[:, 1] <= h - 1)


def sensitivity(robot: Robot, q: np.ndarray, base: np.ndarray) -> np.ndarray:
    """(Dq,) mean |image(q + 1° e_j) − image(q)| in grey levels per pixel, for each joint j; base = image(q).

    Pose i steps joint i mod Dq only: each joint's mean is over n / Dq uniform poses (the same expectation as
    stepping every joint of every pose) for one extra render per pose instead of Dq — software GL is the cost.
    """
    joint = np.arange(len(q)) % robot.dq                                     # (N,) which joint pose i steps
    step = q.copy()
    step[np.arange(len(q)), joint] += STEP_RAD     # may leave the workspace by 1°; within the limits' tolerance
    diff = np.abs(robot.render(step).astype(np.float32) - base.astype(np.float32)).mean(axis=(1, 2))   # (N,)
    return np.array([diff[joint == j].mean() for j in range(robot.dq)])


def measure(camera: str, q: np.ndarray, n_check: int) -> dict:
    with Robot.load(ROBOT, workspace=WORKSPACE, camera=camera) as robot:
        images = robot.render(q)                                             # (N, H, W) uint8
        covered = arm_coverage(images, background(robot))                   # (N,)
        return {"coverage": covered.mean(), "coverage_head": covered[:n_check].mean(),
                "coverage_check": segmented_coverage(robot, q[:n_check]).mean(),
                "in_view": ee_in_view(robot, q).mean(), "sensitivity": sensitivity(robot, q, images),
                "fovy": float(robot.model.camera(camera).fovy[0]), "joints": robot.joint_names}


def write_sheet(out_png: Path, seed: int) -> Path:
    """16 uniform poses of the camera workspace through generate (default camera) and write_contact_sheet."""
    with tempfile.TemporaryDirectory() as tmp:
        store = generate(DatagenConfig(robot=ROBOT, n=16, seed=seed, workspace=WORKSPACE,
                                       out=Path(tmp) / "sheet.zarr"), progress=False)
        return write_contact_sheet(store, out_png, n=16)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=2000, help="poses, uniform in the camera workspace")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sheet", type=Path, default=None, help="also write a 16-pose contact sheet PNG here")
    args = parser.parse_args()
    t0 = time.perf_counter()
    ranges = Robot.load(ROBOT, workspace=WORKSPACE).sampling_ranges            # (Dq, 2) rad
    q = np.random.default_rng(args.seed).uniform(*ranges.T, size=(args.n, len(ranges)))   # (n, Dq) rad
    old, new = (measure(CAMERAS[k], q, min(args.n, N_CHECK)) for k in ("old", "new"))
    print(f"nao_arm, {args.n} uniform poses of workspace {WORKSPACE!r} {np.round(ranges, 3).tolist()} rad, "
          f"56 x 80 grayscale")
    print(f"{'':42s}{'old: eye':>14s}{'new: CameraBottom':>20s}{'new/old':>10s}")
    fovy = ("vertical field of view (deg)", old["fovy"], new["fovy"])
    print(f"{fovy[0]:42s}{fovy[1]:14.2f}{fovy[2]:20.2f}{fovy[2] / fovy[1]:10.2f}")
    rows = [("arm coverage (fraction of px)", old["coverage"], new["coverage"]),
            (f"  first {min(args.n, N_CHECK)} poses", old["coverage_head"], new["coverage_head"]),
            ("  same, exact (segmentation)", old["coverage_check"], new["coverage_check"]),
            ("ee inside the image (fraction)", old["in_view"], new["in_view"])]
    rows += [(f"|d image| per 1 deg {j} (grey)", a, b)
             for j, a, b in zip(old["joints"], old["sensitivity"], new["sensitivity"])]
    rows.append(("|d image| per 1 deg, mean (grey)", old["sensitivity"].mean(), new["sensitivity"].mean()))
    for name, a, b in rows:
        print(f"{name:42s}{a:14.4f}{b:20.4f}{b / a:10.2f}")
    if args.sheet is not None:
        print(f"contact sheet: {write_sheet(args.sheet, args.seed)}")
    print(f"({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
