"""Benchmark: issue 33's table, one arm per row, every step the command a user types, on the defaults.

    MUJOCO_GL=egl .venv/bin/python bench/foreign_arms.py [--arms ur5 so_arm ...] [--n 3000] [--epochs 40]
        [--trials 50] [--pixel-size lean|pixel_aif|splat] [--pixel-lr LR] [--pixel-schedule constant|cosine|wsd]
        [--pixel-loss cross_entropy|mse] [--pixel-inputs products|unit|kinematic] [--gpr-n 6000]
        [--add] [--mount [auto|JOINT|@K ...]] [--masked] [--work bench_out/foreign]
        [--kinematics-only | --pixel-only] [--quick]

Per arm, in a folder of its own (its own MLflow store): `robot init` (a file: the visuals it can load, nothing
edited by hand) and `robot camera`; `train gpr` of ee_xyz and of ee_rot (the ee's orientation) on a store of
--gpr-n poses without images, and the GPR levels (level 1, ee_xyz alone and with ee_rot); then `datagen` (--n
uniform poses, the record's image size), `train pixel` and `train encoder` and the pixel levels 1–3 with and without
the encoder (its floor row: perception started at the truth, per joint), `evaluate reaching` with the GPR and the
joints (AIF against the PD baseline). `--kinematics-only`: the GPR columns and reaching, no images. `--mount`:
`robot camera --mount auto` (or the joints given) adds cameras riding on links, and the pixel rows perceive through
every camera (a decoder each); `--masked`: those cameras draw only their link and the bodies beyond; `--add`:
`robot camera --add`'s second fixed camera too.
The floor of a joint datagen's observability check does not see is in parentheses;
the worst floor over the others is the issue's bar (≤ 2°). Prints one markdown row per arm and the wall minutes of
each step (2 CPU cores: the recipe's CPU time) and writes them to <work>/table.md. Arms: the three shipped ones and
arms of packages in the test extra the project did not write (example-robot-data, dm_control), `--visual` chosen as
a new user would (mesh where MuJoCo loads them, else collision; TALOS without its meshes: primitives).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import importlib.metadata
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from bodyschema.datagen.body.camera_choice import FURTHER
from bodyschema.datagen.body.camera_mount import mounted_names
from bodyschema.datagen.body.record import read_record, shipped_dir, write_record
from bodyschema.datagen.body.robot import Robot

ERD = "cmeel.prefix/share/example-robot-data/robots"
FILES = {   # name → (distribution, file inside it, robot init's --visual)
    "ur5": ("example-robot-data", f"{ERD}/ur_description/urdf/ur5_robot.urdf", "collision"),
    "panda_urdf": ("example-robot-data", f"{ERD}/panda_description/urdf/panda.urdf", "collision"),
    "talos_bare": ("example-robot-data", f"{ERD}/talos_data/robots/talos_full_v2.urdf", "primitives"),
    "jaco": ("dm_control", "dm_control/third_party/kinova/jaco_arm.xml", "mesh"),
    "so_arm": ("example-robot-data", f"{ERD}/so_arm_description/urdf/so101.urdf", "collision"),
    "z1": ("example-robot-data", f"{ERD}/z1_description/urdf/z1.urdf", "collision"),
}
SHIPPED = ("nao_arm", "panda", "planar2")


def bodyschema(args: list[str], log: Path) -> tuple[str, float]:
    """Runs one command as a user would; its output goes to log; stops the arm on failure."""
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "bodyschema.cli", *args], capture_output=True, text=True)
    seconds = time.monotonic() - start
    with log.open("a") as out:
        out.write(f"$ bodyschema {' '.join(args)}  # {seconds:.1f} s, exit {done.returncode}\n")
        out.write(f"{done.stdout}{done.stderr}\n")
    if done.returncode != 0:
        tail = done.stderr.strip()[-400:]
        raise RuntimeError(f"`bodyschema {' '.join(args[:3])}` exit {done.returncode}: {tail}")
    return done.stdout + done.stderr, seconds


def registered(output: str) -> str:
    """The `models:/<name>/<version>` a train command registered."""
    found = re.findall(r"models:/[\w.\-]+/\d+", output)
    if not found:
        raise RuntimeError(f"train printed no registered model: {output[-400:]}")
    return found[-1]


def robot_of(name: str, folder: Path, log: Path, minutes: dict[str, float], cameras: list[str]) -> str:
    """The --robot argument: a shipped name, or the record `robot init` + `robot camera` write for a file;
    `cameras`: `robot camera`'s flags that add cameras (a shipped arm: on a copy of its record)."""
    record = folder / f"{name}.toml"
    if name in SHIPPED:
        if not cameras:
            return name
        shipped = read_record(shipped_dir() / f"{name}.toml")
        write_record(dataclasses.replace(shipped, name=f"{name}_mounted", model=str(shipped.model_path),
                                         base=folder), record)
        _, camera_s = bodyschema(["robot", "camera", str(record), *joint_at(cameras, record)], log)
        minutes["camera"] = camera_s / 60
        return str(record)
    dist, relative, visual = FILES[name]
    model = Path(importlib.metadata.distribution(dist).locate_file(relative))
    if name == "talos_bare":                     # the URDF alone: none of its meshes on disk
        shutil.copy(model, folder / "model.urdf")
        model = folder / "model.urdf"
    _, init_s = bodyschema(["robot", "init", str(model), "--visual", visual, "--out", str(record)], log)
    _, camera_s = bodyschema(["robot", "camera", str(record), *joint_at(cameras, record)], log)
    minutes["init+camera"] = (init_s + camera_s) / 60
    return str(record)


def levels_rows(run: Path) -> dict[str, dict[str, str]]:
    with (run / "latest" / "summary.csv").open() as f:
        return {row["level"]: row for row in csv.DictReader(f)}


FLAGGED = re.compile(r"^ +(\S+)(?: +[\d.]+){3} +(?:< [\d.]+ (?:px|%)/°|on its axis): not seen$", re.MULTILINE)
JOINT_ROW = re.compile(r"^ +(\S+)(?: +[\d.]+){3}(?: +(?:<|on its axis).*)?$", re.MULTILINE)


def unseen_joints(datagen_output: str) -> set[str]:
    """The joints datagen's observability check flags in every camera's table (several cameras: seen by one is seen)."""
    listed, flagged = JOINT_ROW.findall(datagen_output), FLAGGED.findall(datagen_output)
    if "observability:" in datagen_output and not listed:
        raise RuntimeError("datagen's observability table has no joint row this script can read: update JOINT_ROW")
    return {j for j in set(flagged) if flagged.count(j) == listed.count(j)}


def floors(rows: dict[str, dict[str, str]]) -> dict[str, float]:
    """The floor row's mean |error| per joint (°), by joint name."""
    prefix = "joint_err_deg/"
    return {k[len(prefix):]: float(v) for k, v in rows.get("floor", {}).items() if k.startswith(prefix) and v}


def floor_text(per_joint: dict[str, float], unseen: set[str]) -> str:
    """'8.1, 18.6, (156)': a joint the observability check does not see in parentheses."""
    return ", ".join(f"({v:.1f})" if j in unseen else f"{v:.1f}" for j, v in per_joint.items())


def worst_seen(per_joint: dict[str, float], unseen: set[str]) -> str:
    """The bar's figure: the highest floor over the joints the check calls seen (issue 33: ≤ 2°)."""
    seen = [v for j, v in per_joint.items() if j not in unseen]
    return f"{max(seen):.1f}" if seen else "–"


def measure(name: str, work: Path, o: argparse.Namespace) -> dict[str, str]:
    folder = work / name
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    log = folder / "commands.log"
    common = ["--tracking-uri", f"sqlite:///{folder}/mlflow.db"]
    minutes: dict[str, float] = {}
    robot = robot_of(name, folder, log, minutes, camera_flags(o))
    kinematics, gpr = ({"arm": name}, {}) if o.pixel_only else gpr_levels(name, robot, folder, common, o, log,
                                                                           minutes)
    if o.kinematics_only:
        return {**kinematics, **reaching(robot, gpr["ee_xyz"], folder, common, o, log, minutes),
                "recipe minutes": f"{sum(minutes.values()):.1f}",
                "steps": ", ".join(f"{k} {v:.1f}" for k, v in minutes.items())}
    data = folder / "data.zarr"
    out, s = bodyschema(["datagen", "--robot", robot, "--n", str(o.n), "--out", str(data), "--no-progress"], log)
    minutes["datagen"], ms_per_image, unseen = s / 60, 1000 * s / o.n, unseen_joints(out)
    train = [*common, "--run-root", str(folder / "runs"), "--no-progress", "--data", str(data)]
    pixel = []                                     # a decoder per camera: the record's, the added, the mounted ones
    added = [FURTHER] if o.add else []
    for modality in ("image", *(f"image_{name}" for name in [*added, *mounted_names(len(o.mount))])):
        out, s = bodyschema(["train", "pixel", *train, "--modality", modality, "--epochs", str(o.epochs),
                             "--size", o.pixel_size, *(["--lr", str(o.pixel_lr)] if o.pixel_lr else []),
                             *(["--lr-schedule", o.pixel_schedule] if o.pixel_schedule else []),
                             *(["--loss", o.pixel_loss] if o.pixel_loss else []),
                             *(["--inputs", o.pixel_inputs] if o.pixel_inputs else [])], log)
        pixel += ["--model", registered(out)]
        minutes[f"train pixel {modality}"] = s / 60
    out, s = bodyschema(["train", "encoder", *train, "--epochs", str(o.epochs)], log)
    encoder, minutes["train encoder"] = registered(out), s / 60
    _, s = bodyschema(["evaluate", "levels", *levels_flags(common, o), *pixel, "--encoder", encoder,
                       "--multistart", "0", "--out", str(folder / "levels_pixel")], log)
    minutes["levels pixel"] = s / 60
    px = levels_rows(folder / "levels_pixel")
    reached = {} if o.pixel_only else reaching(robot, gpr["ee_xyz"], folder, common, o, log, minutes)
    level = {k: f"{float(px[k]['joint_err_deg']):.2f}" for k in px if k != "floor"}
    per_joint = floors(px)
    return {**kinematics,
            "pixel floor per joint (°), (not seen)": floor_text(per_joint, unseen),
            "worst seen joint's floor (°)": worst_seen(per_joint, unseen),
            "pixel L1 / L2 / L3 (°)": " / ".join(level.get(k, "–") for k in ("1", "2", "3")),
            "+ encoder": " / ".join(level.get(k, "–") for k in ("1+enc", "2+enc", "3+enc")),
            **reached, "datagen ms/image": f"{ms_per_image:.1f}", "recipe minutes": f"{sum(minutes.values()):.1f}",
            "steps": ", ".join(f"{k} {v:.1f}" for k, v in minutes.items())}


def camera_flags(o: argparse.Namespace) -> list[str]:
    """`robot camera`'s flags for the cameras asked beside the fixed view (`@K` in --mount: see joint_at)."""
    return [*(["--add"] if o.add else []), *(["--mount", *o.mount] if o.mount else []),
            *(["--masked"] if o.masked else [])]


def joint_at(flags: list[str], record: Path | str) -> list[str]:
    """`flags` with each `@K` replaced by the robot's K-th joint (1-based): one recipe for every arm, e.g. `--mount @2
    auto` (a camera on the link after the first joint, then the one `auto` picks)."""
    if not any(f.startswith("@") for f in flags):
        return flags
    with Robot.load(record) as robot:
        return [robot.joint_names[int(f[1:]) - 1] if f.startswith("@") else f for f in flags]


def levels_flags(common: list[str], o: argparse.Namespace) -> list[str]:
    """What every `evaluate levels` of the table shares: the arm's MLflow store, no bars or plots, o.trials × 1 run."""
    return [*common, "--no-progress", "--no-plots", "--trials", str(o.trials), "--runs", "1"]


def gpr_levels(name: str, robot: str, folder: Path, common: list[str], o: argparse.Namespace, log: Path,
               minutes: dict[str, float]) -> tuple[dict[str, str], dict[str, str]]:
    """GPRs of ee_xyz and ee_rot on a store of their own without images, as a user would make (a 7-joint arm's
    orientation needs more poses than the images give), and level 1 through ee_xyz alone and with ee_rot: the
    table's GPR columns, and the registered GPRs by modality."""
    kin = folder / "kinematics.zarr"
    _, s = bodyschema(["datagen", "--robot", robot, "--n", str(o.gpr_n), "--out", str(kin), "--no-progress",
                       "--no-images", "--workspace", "camera"], log)
    minutes["datagen kinematics"] = s / 60
    gpr = {}
    for modality in ("ee_xyz", "ee_rot"):
        out, s = bodyschema(["train", "gpr", *common, "--run-root", str(folder / "runs"), "--no-progress",
                             "--data", str(kin), "--modality", modality], log)
        gpr[modality], minutes[f"train gpr {modality}"] = registered(out), s / 60
    level_1 = {}
    for sensed in (("ee_xyz",), ("ee_xyz", "ee_rot")):
        models = [arg for m in sensed for arg in ("--model", gpr[m])]
        out_dir = folder / f"levels_gpr_{'_'.join(sensed)}"
        _, s = bodyschema(["evaluate", "levels", *levels_flags(common, o), *models, "--levels", "1",
                           "--multistart", "0", "--no-floor", "--out", str(out_dir)], log)
        minutes[f"levels gpr {'+'.join(sensed)}"] = s / 60
        level_1[sensed] = f"{float(levels_rows(out_dir)['1']['joint_err_deg']):.2f}"
    return {"arm": name, "GPR L1 (°)": level_1[("ee_xyz",)],
            "GPR L1, ee_xyz + ee_rot (°)": level_1[("ee_xyz", "ee_rot")]}, gpr


def reaching(robot: str, gpr: str, folder: Path, common: list[str], o: argparse.Namespace, log: Path,
             minutes: dict[str, float]) -> dict[str, str]:
    """`evaluate reaching` with the GPR of ee_xyz and the joints: the AIF's and the PD baseline's success (%)."""
    reach = [*common, "--no-progress", "--trials", str(o.reach_trials)]
    joints = f"analytic:{robot}:joints"
    _, s = bodyschema(["evaluate", "reaching", *reach, "--robot", robot, "--model", gpr, "--model", joints,
                       "--out", str(folder / "reaching")], log)
    minutes["reaching"] = s / 60
    with (folder / "reaching" / "latest" / "summary.csv").open() as f:
        success = {row["controller"]: 100 * float(row["success"]) for row in csv.DictReader(f)}
    return {"reaching AIF / PD (%)": f"{success.get('aif', float('nan')):.0f} / {success.get('pd', float('nan')):.0f}"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=[*FILES, *SHIPPED])
    parser.add_argument("--n", type=int, default=3000, help="poses with images (the pixel decoder and encoder)")
    parser.add_argument("--gpr-n", type=int, default=6000, help="poses without images (the GPRs; a 7-joint arm's "
                        "orientation has 3^7 features: 3 000 poses fit it to 0.4 σ, 6 000 to 0.002 σ)")
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--pixel-size", default="lean", help="train pixel's --size (models/pixel.py SIZES)")
    parser.add_argument("--pixel-lr", type=float, default=None, help="train pixel's --lr (default: the size's)")
    parser.add_argument("--pixel-schedule", default=None, help="train pixel's --lr-schedule (default: the size's)")
    parser.add_argument("--pixel-loss", default=None, help="train pixel's --loss (default: the size's; the README's "
                        "nine-arm table: mse)")
    parser.add_argument("--pixel-inputs", default=None, help="train pixel's --inputs (default: products; unit: the "
                        "decoders before 2026-11-30, models/pose_inputs.py)")
    parser.add_argument("--mount", nargs="*", default=None, metavar="auto|JOINT|@K", help="`robot camera --mount "
                        "...` (alone: auto; @K: the arm's K-th joint): cameras riding on links, a decoder each, "
                        "perceived with the first (datagen/body/camera_mount.py)")
    parser.add_argument("--masked", action="store_true", help="`robot camera --masked`: the mounted cameras draw "
                        "only their link and the bodies beyond")
    parser.add_argument("--add", action="store_true", help="`robot camera --add`: a second fixed camera")
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--reach-trials", type=int, default=20)
    parser.add_argument("--work", type=Path, default=Path("bench_out/foreign"))
    parser.add_argument("--kinematics-only", action="store_true", help="no images: the GPR columns and reaching")
    parser.add_argument("--pixel-only", action="store_true", help="the pixel columns alone (no GPR, no reaching)")
    parser.add_argument("--quick", action="store_true", help="tiny sizes: checks the script, not the arms")
    o = parser.parse_args()
    o.mount = (o.mount or ["auto"]) if o.mount is not None else []
    if o.quick:
        o.n, o.gpr_n, o.epochs, o.trials, o.reach_trials = 200, 200, 1, 3, 2
    o.work.mkdir(parents=True, exist_ok=True)
    table = o.work / "table.md"
    header = None
    for name in o.arms:
        try:
            row = measure(name, o.work.resolve(), o)
        except RuntimeError as e:
            row = {"arm": name, "GPR L1 (°)": f"failed: {e}"}
        if header is None:
            header = list(row) if len(row) > 2 else None
            if header:
                line = "| " + " | ".join(header) + " |\n|" + "---|" * len(header) + "\n"
                table.write_text(line)
                print(line, end="")
        line = "| " + " | ".join(row.get(k, "") for k in (header or row)) + " |\n"
        with table.open("a") as f:
            f.write(line)
        print(line, end="", flush=True)


if __name__ == "__main__":
    main()
