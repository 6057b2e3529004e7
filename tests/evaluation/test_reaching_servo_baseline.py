"""The reaching baseline on position servos (issue 33, item 5): the target's joint pose plus the servo's gravity
feed-forward from the model under Earth gravity. It holds a pose without sag, and reaches ≥ 95 % of seeded goals
within 10 mm on arms the project did not tune (dm_control's Jaco, a UR5 from its URDF on the README's table-top
box); TALOS's left arm does once its servos' kv is integrated implicitly (bench/pd_baseline.py)."""

import dataclasses
import importlib.metadata
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bodyschema.control.loop import ServoPolicy, rollout
from bodyschema.control.sim import ArmBatch, control_substeps
from bodyschema.datagen.body.build import build_model
from bodyschema.datagen.body.infer import inertia_gains, infer_record
from bodyschema.datagen.body.record import RobotRecord
from bodyschema.datagen.body.robot import Robot
from bodyschema.evaluation.core.sensing import Sensors
from bodyschema.evaluation.reaching.servo_baseline import servo_targets

ERD = "cmeel.prefix/share/example-robot-data/robots"
UR5_BOX = ((-0.8, 0.8), (-2.2, -0.9), (0.6, 2.2), (-2.4, -0.6), (-1.6, 1.6))    # README's table-top box


def _package_file(dist: str, relative: str) -> Path:
    try:
        return Path(importlib.metadata.distribution(dist).locate_file(relative))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip(f"{dist} is not installed (pip install -e '.[test]')")


def _ur5_table_top() -> RobotRecord:
    """The README's UR5 recipe: `robot init --visual collision`, wrist_3 dropped and held, the table-top box."""
    record = infer_record(_package_file("example-robot-data", f"{ERD}/ur_description/urdf/ur5_robot.urdf"),
                          visual="collision")
    gains = {k: record.actuators[k][:5] for k in ("kp", "kv")}
    return dataclasses.replace(record, joints=record.joints[:5], hold={"wrist_3_joint": 0.0},
                               workspaces={"full": UR5_BOX, "camera": UR5_BOX},
                               actuators={"kind": "servos", **gains})


def _talos_left_arm4() -> RobotRecord:
    model = _package_file("example-robot-data", f"{ERD}/talos_data/robots/talos_full_v2.urdf")
    box = ((-1.0, 0.7), (0.1, 2.0), (-1.5, 1.5), (-2.0, -0.1))
    record = RobotRecord(name="talos_left_arm", model=str(model), visual="collision", collisions="none",
                         joints=tuple(f"arm_left_{i}_joint" for i in range(1, 5)), hold={"torso_2_joint": 0.2},
                         ee={"body": "arm_left_7_link", "offset": [0.0, 0.0, -0.1]}, image_size=(48, 48),
                         workspaces={"full": box, "camera": box}, base=model.parent,
                         camera={"name": "auto", "pos": [2.0, 0.0, 1.0], "xyaxes": [0, 1, 0, 0, 0, 1], "fovy": 45})
    kp, kv = inertia_gains(build_model(record).model, np.array(box), sag=True)
    return dataclasses.replace(record, actuators={"kind": "servos", "kp": kp, "kv": kv})


def _reach(robot, trials: int = 10, seconds: float = 3.0, rate: float = 50.0, seed: int = 0,
           feed_forward: bool = True) -> np.ndarray:
    """Final ee errors (N,) m of the servo baseline on seeded uniform targets from uniform starts at rest."""
    rng = np.random.default_rng(seed)
    box = robot.sampling_ranges
    q_target, q_start = rng.uniform(box[:, 0], box[:, 1], (2, trials, robot.dq))
    ctrl = servo_targets(robot, q_target) if feed_forward else q_target
    out = rollout(robot, ServoPolicy(ctrl), q_start, {}, robot.fk(q_target), Sensors((), {}, frozenset(), rng),
                  int(round(seconds * rate)), control_substeps(rate, robot.model.opt.timestep))
    assert not out.failed.any()
    return out.ee_err[-1]


@pytest.mark.parametrize("arm", ["jaco", "ur5"])
def test_arms_from_files_on_their_servos_reach_their_goals(arm):
    record = infer_record(_package_file("dm_control", "dm_control/third_party/kinova/jaco_arm.xml")) \
        if arm == "jaco" else _ur5_table_top()
    with Robot.load(record, actuators="position") as robot:
        assert robot.actuation == "position" and robot.record.actuators["kind"] == "servos"   # inferred servos
        err = _reach(robot)
    assert (err < 0.010).mean() >= 0.95, f"final ee errors {np.round(1e3 * err, 1)} mm"


def test_the_feed_forward_is_the_models_gravity_torque_over_the_servo_gain_under_earths_gravity():
    q = np.random.default_rng(1).uniform(-0.5, 0.5, (5, 4)) + np.array([0.0, 0.5, 0.0, -0.8])   # (5, 4) rad
    with Robot.load("nao_arm") as earth, Robot.load("nao_arm", gravity=24.79) as jupiter:
        ctrl = servo_targets(earth, q)
        np.testing.assert_array_equal(servo_targets(jupiter, q), ctrl)     # identified on Earth, used on Jupiter
        m, d = earth.model, mujoco.MjData(earth.model)
        kp = m.actuator_gainprm[:, 0]
        for q_i, c_i in zip(q, ctrl):
            d.qpos[:], d.qvel[:] = q_i, 0.0
            mujoco.mj_forward(m, d)
            np.testing.assert_allclose(c_i - q_i, (d.qfrc_bias - d.qfrc_passive) / kp, rtol=1e-9, atol=1e-12)
        assert np.abs(ctrl - q).max() > 0.01                               # nao_arm's shoulder: ~1° of sag to take
        held, sagged = ArmBatch(earth, q), ArmBatch(earth, q)              # start at rest on q, servos on ctrl or q
        for _ in range(50):
            held.step(ctrl, 10)
            sagged.step(q, 10)
    assert np.abs(held.q - q).max() < 1e-4                                # holds the pose: no sag
    assert np.abs(sagged.q - q).max() > 0.01                               # the bare pose sags


def test_talos_reaches_because_the_servos_we_add_integrate_kv_implicitly():
    """TALOS's file names no integrator (MuJoCo's Euler): with kv explicit, h·kv/M > 2 on arm_left_3 near a straight
    elbow and the joint oscillates whatever the command. The robot builder makes the servos it adds implicit
    (`implicitfast`, as the shipped arms' MJCFs say); with that the feed-forward reaches every goal."""
    with Robot.load(_talos_left_arm4(), actuators="position") as talos:
        assert talos.model.dof_frictionloss.min() > 0                      # dry friction, stuck within f / kp
        assert talos.model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        err = _reach(talos)
        old = _reach(talos, feed_forward=False)
    assert (err < 0.010).mean() >= 0.95, f"final ee errors {np.round(1e3 * err, 1)} mm"
    assert err.mean() < 0.5 * old.mean()                                   # the sag the bare pose leaves
