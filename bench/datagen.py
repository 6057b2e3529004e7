"""Benchmark: `generate` throughput against bare MuJoCo loops on the same model, measured in the same run.

    .venv/bin/python bench/datagen.py [--n-images 1500] [--n-kinematic 100000]

nao_arm at 56 x 80 px. Prints samples/s of
  - generate with images, 1 worker and 2 workers (loky), vs a bare `mujoco.Renderer` loop (targets: >= 80 % with
    1 worker, >= 1.7x that with 2 workers);
  - generate kinematics only (q, ee_xyz, ee_pixel, jacobian), vs a bare `mj_kinematics` loop (target >= 50 %).
The generate figures are end to end (Robot load, sampling, rendering, Jacobians, Zstd, Zarr writes, markers); loky
workers are warmed up by a tiny job first, so the figures are steady-state throughput, not process start-up.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from bodyschema.datagen.robot import Robot  # sets MUJOCO_GL=egl before mujoco is imported

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from bodyschema.datagen.config import DatagenConfig  # noqa: E402
from bodyschema.datagen.generate import generate  # noqa: E402

ROBOT, SIZE = "nao_arm", (56, 80)


def poses(robot: Robot, n: int) -> np.ndarray:
    r = robot.sampling_ranges
    return r[:, 0] + np.diff(r, axis=1)[:, 0] * np.random.default_rng(0).random((n, robot.dq))  # (n, Dq)


def bare_render(n: int) -> float:
    """Samples/s of set qpos -> mj_kinematics -> update_scene -> render (RGB), nothing else."""
    robot = Robot.load(ROBOT, image_size=SIZE)
    m, d, q = robot.model, mujoco.MjData(robot.model), poses(robot, n)
    qadr = [m.jnt_qposadr[m.joint(j).id] for j in robot.joint_names]
    with mujoco.Renderer(m, height=SIZE[0], width=SIZE[1]) as renderer:
        renderer.update_scene(d, robot.camera_name)
        renderer.render()  # GL warm-up
        t0 = time.perf_counter()
        for i in range(n):
            d.qpos[qadr] = q[i]
            mujoco.mj_kinematics(m, d)
            renderer.update_scene(d, robot.camera_name)
            renderer.render()
        return n / (time.perf_counter() - t0)


def bare_kinematics(n: int) -> float:
    """Samples/s of set qpos -> mj_kinematics -> read the ee site, nothing else."""
    robot = Robot.load(ROBOT, image_size=SIZE)
    m, d, q = robot.model, mujoco.MjData(robot.model), poses(robot, n)
    qadr = [m.jnt_qposadr[m.joint(j).id] for j in robot.joint_names]
    site, out = m.site("ee").id, np.empty((n, 3))
    t0 = time.perf_counter()
    for i in range(n):
        d.qpos[qadr] = q[i]
        mujoco.mj_kinematics(m, d)
        out[i] = d.site_xpos[site]
    return n / (time.perf_counter() - t0)


def timed_generate(root: Path, name: str, **kwargs) -> float:
    config = DatagenConfig(robot=ROBOT, image_size=SIZE, out=root / name, **kwargs)
    t0 = time.perf_counter()
    generate(config, progress=False)
    rate = config.n / (time.perf_counter() - t0)
    shutil.rmtree(root / name)
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-images", type=int, default=1500)
    parser.add_argument("--n-kinematic", type=int, default=100_000)
    args = parser.parse_args()
    print(f"datagen benchmark: {ROBOT} {SIZE[0]}x{SIZE[1]} px, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory(prefix="bench-datagen-") as tmp:
        root = Path(tmp)
        timed_generate(root, "warmup.zarr", n=64, shard_size=16, workers=2)  # start the loky workers
        ni, nk = args.n_images, args.n_kinematic
        img_shard = max(1, ni // 8)  # 8 shards: both workers stay busy to the end
        render = bare_render(ni)
        gen1 = timed_generate(root, "img1.zarr", n=ni, shard_size=img_shard, workers=1)
        gen2 = timed_generate(root, "img2.zarr", n=ni, shard_size=img_shard, workers=2)
        kin = bare_kinematics(nk)
        genk = timed_generate(root, "kin.zarr", n=nk, images=False, shard_size=max(1, nk // 8), workers=1)
    print(f"{'':38}{'samples/s':>12}{'ratio':>10}{'target':>10}")
    print(f"{'bare mujoco.Renderer loop':38}{render:12.0f}")
    print(f"{'generate, images, 1 worker':38}{gen1:12.0f}{gen1 / render:10.2f}{'>= 0.80':>10}")
    print(f"{'generate, images, 2 workers':38}{gen2:12.0f}{gen2 / gen1:9.2f}x{'>= 1.7x':>10}  (vs 1 worker)")
    print(f"{'bare mj_kinematics loop':38}{kin:12.0f}")
    print(f"{'generate, kinematics only, 1 worker':38}{genk:12.0f}{genk / kin:10.2f}{'>= 0.50':>10}")


if __name__ == "__main__":
    main()
