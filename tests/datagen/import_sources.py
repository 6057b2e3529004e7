"""Small recordings for the import tests, in the layouts labs and robot-learning datasets use: a folder of images
plus a CSV of angles, and an HDF5 file of demo episodes (data/demo_i/obs/<key>). Frames are planar2 renders, so
what an import gives back can be checked against the robot."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bodyschema.datagen.body.robot import Robot

SIZE = (24, 24)          # px: rendering 24 planar2 frames takes well under a second


def planar2_frames(n: int, seed: int = 0, rgb: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(q (n, 2) rad inside planar2's workspace, images (n, H, W[, 3]) uint8) rendered by the robot."""
    with Robot.load("planar2", image_size=SIZE, rgb=rgb) as robot:
        low, high = robot.sampling_ranges.T
        q = np.random.default_rng(seed).uniform(low, high, size=(n, 2))
        return q, robot.observe(q)["image"]


def write_folder(folder: Path, q: np.ndarray, images: np.ndarray | None, names=("shoulder", "elbow"),
                 order=None, deg: bool = True, header: bool = True) -> Path:
    """img0.png … and angles.csv: one row per image, q's columns (joints `names`) written in `order` (indices;
    None: as they are), in deg or rad. images None: the CSV alone."""
    import cv2

    folder.mkdir(parents=True)
    for i, image in enumerate(images if images is not None else []):
        cv2.imwrite(str(folder / f"img{i}.png"), image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    order = list(range(q.shape[1])) if order is None else list(order)
    values = np.rad2deg(q) if deg else q
    lines = [",".join(names[i] for i in order)] if header else []
    lines += [",".join(repr(float(v)) for v in row[order]) for row in values]
    (folder / "angles.csv").write_text("\n".join(lines) + "\n")
    return folder


def write_demo_hdf5(path: Path, q: np.ndarray, images: np.ndarray, episodes: int, ee: np.ndarray | None = None) -> Path:
    """data/demo_<i>/obs/{joint_pos, agentview_image[, eef_pos]}: the frames split into `episodes` episodes."""
    import h5py

    with h5py.File(path, "w") as f:
        for i, rows in enumerate(np.array_split(np.arange(len(q)), episodes)):
            obs = f.create_group(f"data/demo_{i}/obs")
            obs["joint_pos"] = q[rows]
            obs["agentview_image"] = images[rows]
            if ee is not None:
                obs["eef_pos"] = ee[rows]
    return path
