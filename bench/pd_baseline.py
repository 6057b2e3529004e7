"""Benchmark: the reaching benchmark's PD baseline, the old gain rule against the new, per arm in the same run.

    MUJOCO_GL=egl .venv/bin/python bench/pd_baseline.py [--trials 20] [--arms panda ur5 ...] [--actuators torque]

Two tables, one per actuation (`--actuators position|torque|both`).
Torque: per arm, torque motors (`actuators="torque"`), the arm's reaching control rate and duration (its record's
[reaching], else 50 Hz for 3 s), `trials` targets and starts uniform in its sampling workspace (seed 0), the same
for every rule; the PD is handed the target's true joint pose, as in `bodyschema evaluate reaching`:
  old    PDConfig(gains="record"): the record's [pd] (the Panda's libfranka gains; for an arm from a file what
         `robot init` inferred: K_p = (20 rad/s)² × each joint's largest diagonal inertia, critically damped)
         + gravity compensation;
  model  PDConfig(gains="model"): the rule of control/pd_gains.py (computed torque at ω = min(20, 0.4/Δt)
         + bias, springs and dry friction from the model);
  auto   what the benchmark runs (PDConfig()): "record" for tuned [pd] gains, else "model".
Arms: the three shipped ones (nao_arm and planar2 on motors here; their reaching baseline is their position servos)
and arms the project did not tune, from packages of the test extra: dm_control's Kinova Jaco (MJCF), the UR5
(URDF, collision visuals), a Panda from example-robot-data's URDF (7 joints, none of our tuning), TALOS's left
arm (7 joints) and its first 4 joints (the rest held), with the records
`bodyschema robot init` would write (TALOS's: by hand, its servos inferred as `robot init` does; collisions off as
`robot init` sets them: with the torso's collision meshes many uniform goals lie inside the body).
Position: per arm, its position servos (the model's or those `robot init` infers), the same targets and starts:
  old    the servos commanded to the target's joint pose, under the integrator the file names (MuJoCo's Euler
         where it names none): the baseline and the model before issue 33;
  ff     + the servo's gravity feed-forward (evaluation/reaching/servo_baseline.py), the same integrator;
  ff+imp the same with the servos' kv implicit (`implicitfast`, what the robot builder now sets where the file
         names no integrator, as the shipped arms' MJCFs say): what the benchmark runs.
Prints success within 10 mm, mean/max final ee error (mm), mean joint error (°), mean settle time (s), how far
an ee error still moves over the episode's last 10 % (mm, the largest: a servo still oscillating) and the new/old
success ratio. Target: < 2 min on 2
shared cores for both tables at 20 trials.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import time
from pathlib import Path

from bodyschema.datagen.body.robot import Robot  # first: bodyschema sets MUJOCO_GL before mujoco is imported

# isort: split
import mujoco
import numpy as np

from bodyschema.control.loop import ServoPolicy, TorquePolicy, rollout
from bodyschema.control.pd import PDConfig, PDController
from bodyschema.control.robot_defaults import DEFAULTS
from bodyschema.control.sim import control_substeps
from bodyschema.datagen.body.build import build_model
from bodyschema.datagen.body.infer import inertia_gains, infer_record
from bodyschema.datagen.body.record import RobotRecord
from bodyschema.evaluation.core.sensing import Sensors
from bodyschema.evaluation.reaching.servo_baseline import servo_targets

SUCCESS_M = 0.010
ERD = "cmeel.prefix/share/example-robot-data/robots"
UR5 = f"{ERD}/ur_description/urdf/ur5_robot.urdf"
PANDA_URDF = f"{ERD}/panda_description/urdf/panda.urdf"
TALOS_BOX = ((-1.0, 0.7), (0.1, 2.0), (-1.5, 1.5), (-2.0, -0.1), (-1.5, 1.5), (-1.0, 1.0), (-0.5, 0.5))
RULES = {"old": PDConfig(gains="record"), "model": PDConfig(gains="model"), "auto": PDConfig()}
SERVO_RULES = ("old", "ff", "ff+imp")


def _package_file(dist: str, relative: str) -> Path:
    return Path(importlib.metadata.distribution(dist).locate_file(relative))


def talos_record(n_joints: int) -> RobotRecord:
    """TALOS's left arm, its first n_joints moving (the others of the humanoid held), servos as `robot init`
    infers them (the URDF has no actuators) and its collisions off."""
    model = _package_file("example-robot-data", ERD + "/talos_data/robots/talos_full_v2.urdf")
    joints = tuple(f"arm_left_{i}_joint" for i in range(1, n_joints + 1))
    box = TALOS_BOX[:n_joints]
    record = RobotRecord(name=f"talos_left_arm{n_joints}", model=str(model), joints=joints, visual="collision",
                         hold={"torso_2_joint": 0.2, "arm_right_4_joint": -1.0}, collisions="none",
                         ee={"body": "arm_left_7_link", "offset": [0.0, 0.0, -0.1]}, image_size=(48, 48),
                         workspaces={"full": box, "camera": box}, base=model.parent,
                         camera={"name": "auto", "pos": [2.0, 0.0, 1.0], "xyaxes": [0, 1, 0, 0, 0, 1], "fovy": 45})
    kp, kv = inertia_gains(build_model(record).model, np.array(box), sag=True)
    return dataclasses.replace(record, actuators={"kind": "servos", "kp": kp, "kv": kv})


def arms() -> dict:
    return {"panda": "panda", "nao_arm": "nao_arm", "planar2": "planar2",
            "jaco": lambda: infer_record(_package_file("dm_control", "dm_control/third_party/kinova/jaco_arm.xml")),
            "ur5": lambda: infer_record(_package_file("example-robot-data", UR5), visual="collision"),
            "panda_urdf": lambda: infer_record(_package_file("example-robot-data", PANDA_URDF), visual="collision"),
            "talos_left_arm7": lambda: talos_record(7), "talos_left_arm4": lambda: talos_record(4)}


def reach(robot: Robot, config: PDConfig | str, trials: int, seed: int = 0) -> dict:
    """The PD (a PDConfig, torque motors) or the servo baseline (a SERVO_RULES name, position servos) on `trials`
    uniform targets from uniform starts at rest. → metrics"""
    rate = float(robot.record.reaching.get("control_hz", DEFAULTS["control_hz"]))
    seconds = float(robot.record.reaching.get("duration_s", DEFAULTS["duration_s"]))
    rng = np.random.default_rng(seed)
    box = robot.sampling_ranges
    q_target, q_start = rng.uniform(box[:, 0], box[:, 1], (2, trials, robot.dq))        # (N, Dq) rad each
    integrator = robot.model.opt.integrator
    if isinstance(config, PDConfig):
        pd = PDController(robot, config)
        policy, law = TorquePolicy(pd, goal={"joints": q_target}), pd.law
    else:
        policy, law = ServoPolicy(q_target if config == "old" else servo_targets(robot, q_target)), "servo"
        if config != "ff+imp" and "integrator" not in robot.source.text:   # as built before: the file's Euler
            robot.model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    start = time.perf_counter()
    try:
        out = rollout(robot, policy, q_start, {}, robot.fk(q_target), Sensors((), {}, frozenset(), rng),
                      int(round(seconds * rate)), control_substeps(rate, robot.model.opt.timestep))
    finally:
        robot.model.opt.integrator = integrator
    inside = out.ee_err < SUCCESS_M                                                       # (T+1, N)
    settled = [out.t[np.flatnonzero(~inside[:, b])[-1] + 1] for b in range(trials) if inside[-1, b]]
    tail = out.ee_err[-max(len(out.ee_err) // 10, 2):]                                      # the last 10 %
    return {"law": law, "moving_mm": 1e3 * float(np.ptp(tail, axis=0).max()), "success": float(inside[-1].mean()),
            "ee_mm": 1e3 * out.ee_err[-1].mean(),
            "ee_max_mm": 1e3 * out.ee_err[-1].max(), "joint_deg": np.degrees(np.abs(out.q - q_target)).mean(),
            "settle_s": float(np.mean(settled)) if settled else float("nan"), "rate": rate, "seconds": seconds,
            "failed": int(out.failed.sum()), "wall_s": time.perf_counter() - start}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--arms", nargs="*", default=list(arms()))
    parser.add_argument("--actuators", choices=("position", "torque", "both"), default="both")
    args = parser.parse_args()
    table = arms()
    for actuators, rules in (("torque", RULES), ("position", dict(zip(SERVO_RULES, SERVO_RULES)))):
        if args.actuators not in (actuators, "both"):
            continue
        print(f"\n{actuators}: {'arm':17s} {'Dq':>2s} {'Hz':>4s} {'s':>3s} | {'rule':6s} {'law':6s} {'success':>7s} "
              f"{'ee mean/max mm':>15s} {'joint °':>8s} {'settle s':>8s} {'moving mm':>9s} | success / old's")
        for name in args.arms:
            ref = table[name]
            robot = Robot.load(ref() if callable(ref) else ref, actuators=actuators)
            rows = {rule: reach(robot, config, args.trials) for rule, config in rules.items()}
            for rule, r in rows.items():
                old = rows["old"]["success"]
                ratio = "" if rule == "old" else f"{r['success'] / old:.2f}" if old else "old 0 %"
                print(f"{name:17s} {robot.dq:2d} {r['rate']:4.0f} {r['seconds']:3.0f} | {rule:6s} {r['law']:6s} "
                      f"{r['success']:7.0%} {r['ee_mm']:7.1f}/{r['ee_max_mm']:7.1f} {r['joint_deg']:8.2f} "
                      f"{r['settle_s']:8.2f} {r['moving_mm']:9.1f} | {ratio}"
                      + (f"  ({r['failed']} failed)" if r["failed"] else ""))


if __name__ == "__main__":
    main()
