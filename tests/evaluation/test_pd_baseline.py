"""The reaching benchmark's PD baseline on arms it was not tuned for (issue 33, item 5): gains from the arm's own
model and the control period reach ≥ 95 % of seeded reachable goals within 10 mm, on foreign arms (UR5 URDF,
TALOS's left arm) and a shipped one; the gains scale with the arm's inertia and the control rate bounds them."""

import copy
import dataclasses
import importlib.metadata
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bodyschema.control.loop import TorquePolicy, rollout
from bodyschema.control.pd import PDConfig, PDController
from bodyschema.control.pd_gains import RATE_FRACTION, ModelLaw, bandwidth, inferred_pd
from bodyschema.control.sim import control_substeps
from bodyschema.datagen.body.build import build_model
from bodyschema.datagen.body.infer import SERVO_RAD_S, inertia_gains, infer_record
from bodyschema.datagen.body.record import RobotRecord
from bodyschema.datagen.body.robot import Robot
from bodyschema.evaluation.core.sensing import Sensors

ERD = "cmeel.prefix/share/example-robot-data/robots"


def _package_file(dist: str, relative: str) -> Path:
    try:
        return Path(importlib.metadata.distribution(dist).locate_file(relative))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip(f"{dist} is not installed (pip install -e '.[test]')")


def _talos_left_arm(n_joints: int = 4) -> RobotRecord:
    """TALOS's left arm, its first n_joints moving, written by hand; servos as `robot init` infers them (the URDF has
    none), collisions off (the torso's meshes would hide goals inside the body). Its joints have dry friction."""
    model = _package_file("example-robot-data", f"{ERD}/talos_data/robots/talos_full_v2.urdf")
    box = ((-1.0, 0.7), (0.1, 2.0), (-1.5, 1.5), (-2.0, -0.1))[:n_joints]
    record = RobotRecord(name="talos_left_arm", model=str(model), visual="collision", collisions="none",
                         joints=tuple(f"arm_left_{i}_joint" for i in range(1, n_joints + 1)),
                         hold={"torso_2_joint": 0.2}, ee={"body": "arm_left_7_link", "offset": [0.0, 0.0, -0.1]},
                         image_size=(48, 48), workspaces={"full": box, "camera": box}, base=model.parent,
                         camera={"name": "auto", "pos": [2.0, 0.0, 1.0], "xyaxes": [0, 1, 0, 0, 0, 1], "fovy": 45})
    kp, kv = inertia_gains(build_model(record).model, np.array(box), sag=True)
    return dataclasses.replace(record, actuators={"kind": "servos", "kp": kp, "kv": kv})


@pytest.fixture(scope="module")
def ur5():
    record = infer_record(_package_file("example-robot-data", f"{ERD}/ur_description/urdf/ur5_robot.urdf"),
                          visual="collision")
    with Robot.load(record, actuators="torque") as robot:
        yield robot


def _reach(robot, config: PDConfig | None = None, trials: int = 10, rate: float = 50.0, seconds: float = 3.0,
           seed: int = 0) -> tuple[np.ndarray, PDController]:
    """Final ee errors (N,) m of the PD on seeded uniform targets from uniform starts at rest."""
    rng = np.random.default_rng(seed)
    box = robot.sampling_ranges
    q_target, q_start = rng.uniform(box[:, 0], box[:, 1], (2, trials, robot.dq))
    pd = PDController(robot, config or PDConfig())
    out = rollout(robot, TorquePolicy(pd, goal={"joints": q_target}), q_start, {}, robot.fk(q_target),
                  Sensors((), {}, frozenset(), rng), int(round(seconds * rate)),
                  control_substeps(rate, robot.model.opt.timestep))
    assert not out.failed.any()
    return out.ee_err[-1], pd


def test_a_ur5_from_its_urdf_reaches_its_goals_with_gains_from_its_model(ur5):
    assert not ur5.record.pd and inferred_pd(ur5)             # robot init writes no [pd]: the model rule runs
    err, pd = _reach(ur5)
    assert pd.law == "model"
    assert (err < 0.010).mean() >= 0.95, f"final ee errors {np.round(1e3 * err, 1)} mm"


def test_talos_left_arm_with_dry_friction_reaches_its_goals():
    with Robot.load(_talos_left_arm(), actuators="torque") as talos:
        assert talos.model.dof_frictionloss.min() > 0         # the URDF's friction: what sticks a plain PD
        err, pd = _reach(talos)
    assert pd.law == "model"
    assert (err < 0.010).mean() >= 0.95, f"final ee errors {np.round(1e3 * err, 1)} mm"


def test_shipped_arms_keep_their_figures_nao_arm_on_motors_and_the_panda_on_its_tuned_gains():
    with Robot.load("nao_arm", actuators="torque") as nao:
        err, pd = _reach(nao)
    assert pd.law == "model" and (err < 0.010).mean() >= 0.95, f"final ee errors {np.round(1e3 * err, 1)} mm"
    panda = PDController("panda")
    assert panda.law == "record" and panda.config.gains == "auto"          # libfranka's gains, as before


def test_the_gains_follow_the_arms_inertia_and_the_control_rate(ur5):
    model = ur5.model
    heavy = _scaled(model, 2.0)
    q = ur5.sampling_ranges.mean(1)
    limits = model.actuator_ctrlrange
    kp, kd = ModelLaw(model, limits).gains(q, 0.02)
    kp2, kd2 = ModelLaw(heavy, limits).gains(q, 0.02)
    np.testing.assert_allclose(kp2, 2.0 * kp, rtol=1e-9)                  # twice the masses: twice the gains
    np.testing.assert_allclose(kd2, 2.0 * kd, rtol=1e-9)
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    inertia = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, inertia)
    np.testing.assert_allclose(kp, SERVO_RAD_S ** 2 * inertia, rtol=1e-9)   # 50 Hz: the servo bandwidth
    slow, _ = ModelLaw(model, limits).gains(q, 0.1)                           # 10 Hz: the rate bounds ω
    np.testing.assert_allclose(slow, (RATE_FRACTION / 0.1) ** 2 * inertia, rtol=1e-9)
    assert bandwidth(0.1) * 0.1 <= RATE_FRACTION < 0.5                      # the sampled loop's poles stay real


def _scaled(model: mujoco.MjModel, factor: float) -> mujoco.MjModel:
    heavy = copy.copy(model)                                                # a model of its own
    heavy.body_mass[:] *= factor
    heavy.body_inertia[:] *= factor
    heavy.dof_armature[:] *= factor
    return heavy


def test_the_old_rule_and_tuned_gains_stay_available(ur5):
    assert PDController(ur5, PDConfig(gains="record")).law == "record"
    tuned = dataclasses.replace(ur5.record, pd={"kp": [100.0] * 6, "kd": [10.0] * 6})
    assert not inferred_pd(Robot.load(tuned, actuators="torque"))
    assert PDController(Robot.load(tuned, actuators="torque")).law == "record"
    with pytest.raises(ValueError, match="gains must be one of"):
        PDConfig(gains="fast")


def test_robot_inits_gains_are_told_from_a_tuning_after_the_model_changed(ur5):
    with Robot.load(ur5.record, actuators="torque") as drifted:            # masses 20 % up since `robot init`
        for field in ("body_mass", "body_inertia", "dof_armature"):
            getattr(drifted.model, field)[:] *= 1.2
        assert inferred_pd(drifted)                                        # an exact recomputation: False
    tuned = dataclasses.replace(ur5.record, pd={"kp": [100.0] * 6, "kd": [10.0] * 6})   # also kd = 2kp/ω
    assert not inferred_pd(Robot.load(tuned, actuators="torque"))


def test_an_arm_without_motors_is_the_house_error():
    record = dataclasses.replace(_talos_left_arm(), actuators={"kind": "model"})
    with pytest.raises(ValueError, match="a motor on each of its 4 joints"):
        PDController(record)
