"""Render time per image of arms the project did not write, side by side with the shipped nao_arm (one run).

    MUJOCO_GL=egl python bench/robot_render.py [--n 40] [--rounds 5] [--size 64]

Arms (packages of the test extra, nothing downloaded): dm_control's Kinova Jaco (MJCF, STL meshes), example-robot-
data's UR5 (`--visual collision`), Panda (`--visual collision`), TALOS (the humanoid; `robot init` picks its left
arm: collision meshes, and `--visual primitives` on a copy without its meshes). Each arm's record is inferred as
`robot init` writes it; three also through a camera riding on a link (`robot camera --mount auto`: near meshes,
nothing out of view for good). Rounds alternate the arms (load from other jobs hits them alike); the median round is
printed, in ms per image and as a ratio to nao_arm's (issue 33's bar: ≤ 3×).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from bodyschema.datagen.body.camera_mount import choose_mount
from bodyschema.datagen.body.infer import infer_record
from bodyschema.datagen.body.observability import observability
from bodyschema.datagen.body.robot import Robot

ROBOTS = "cmeel.prefix/share/example-robot-data/robots"
MOUNTED_ON = ("jaco (MJCF meshes)", "ur5 (collision)", "talos arm (collision)")   # also timed through a mounted camera


def arms(tmp: Path) -> dict[str, object]:
    robots = Path(importlib.metadata.distribution("example-robot-data").locate_file(ROBOTS))
    jaco = Path(importlib.metadata.distribution("dm_control").locate_file("dm_control/third_party/kinova/jaco_arm.xml"))
    talos = robots / "talos_data/robots/talos_full_v2.urdf"
    bare = tmp / talos.name                                  # the URDF alone: its meshes are not on disk
    shutil.copy(talos, bare)
    return {"nao_arm": "nao_arm",
            "jaco (MJCF meshes)": infer_record(jaco),
            "ur5 (collision)": infer_record(robots / "ur_description/urdf/ur5_robot.urdf", visual="collision"),
            "panda (collision)": infer_record(robots / "panda_description/urdf/panda.urdf", visual="collision"),
            "talos arm (collision)": infer_record(talos, visual="collision"),
            "talos arm (primitives)": infer_record(bare, visual="primitives")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=40, help="images per arm and round")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--size", type=int, default=64, help="image side, px")
    args = parser.parse_args()
    size = (args.size, args.size)
    with tempfile.TemporaryDirectory(prefix="bodyschema-bench-render-") as tmp:
        records = arms(Path(tmp))
        robots = {name: (Robot.load(ref, image_size=size), "image") for name, ref in records.items()}
        for name in MOUNTED_ON:                              # a camera riding on a link (`robot camera --mount auto`)
            robots[f"{name}, mounted camera"] = (Robot.load(with_mounted(records[name], size)), "image_mounted")
    times = {name: [] for name in robots}
    poses = {}
    for name, (robot, camera) in robots.items():
        ranges = robot.sampling_ranges
        poses[name] = np.random.default_rng(0).uniform(ranges[:, 0], ranges[:, 1], (args.n, robot.dq))
        robot.render(poses[name][:2], modality=camera)      # the GL context and the first upload
    for _ in range(args.rounds):
        for name, (robot, camera) in robots.items():
            start = time.perf_counter()
            robot.render(poses[name], modality=camera)
            times[name].append((time.perf_counter() - start) / args.n * 1e3)
    base = float(np.median(times["nao_arm"]))
    print(f"{'arm':38s} {'joints':>6s} {'geoms':>6s} {'ms/image':>9s} {'× nao_arm':>9s}   ({args.size}×{args.size}, "
          f"median of {args.rounds} rounds of {args.n})")
    for name, (robot, _) in robots.items():
        ms = float(np.median(times[name]))
        print(f"{name:38s} {robot.dq:6d} {robot.model.ngeom:6d} {ms:9.2f} {ms / base:9.2f}")
        robot.close()


def with_mounted(record, size: tuple[int, int]):
    """`record` at `size` with the camera `robot camera --mount auto` places beside its own."""
    record = dataclasses.replace(record, image_size=size)
    box = np.array(record.workspaces["camera"])
    with Robot.load(record) as robot:
        fixed = observability(robot, box)
    return dataclasses.replace(record, cameras=(choose_mount(record, box, [fixed])[0],))


if __name__ == "__main__":
    main()
