"""The reaching baseline on position servos: the target's joint pose plus the servo's own gravity feed-forward
(issue 33, item 5).

A MuJoCo servo pushes its joint with gear·(g₀·ctrl + b₀ + b₁·q + b₂·q̇) (`actuator_gainprm[0]`, `actuator_biasprm`;
a `<position>` servo: g₀ = kp, b₀ = 0, b₁ = −kp, b₂ = −kv). Commanded to ctrl = q_d it comes to rest where that push
holds the load, q = q_d − τ_hold/kp: a finite-gain servo sags under gravity (nao_arm: 1.3° on its shoulder, 4.8 mm
of ee error; an inferred servo up to `infer.SAG_RAD`). The rule: command the ctrl whose push at rest at q_d is
the torque that holds q_d,
    ctrl = (τ_hold(q_d) / gear − b₀ − b₁·q_d) / g₀          (= q_d + τ_hold(q_d) / kp for a `<position>` servo)
    τ_hold(q) = qfrc_bias(q, q̇ = 0) − qfrc_passive(q)     gravity (RNE at rest) minus springs,
once per target, on a private copy of the robot's model under Earth gravity (9.81 m/s², as `control.pd.PDController`:
a compensation identified on Earth stays Earth's when the simulated gravity changes), clipped to the ctrlrange
(a target near a joint limit keeps what the clip takes). Dry friction is left: a servo sticks within f / kp of
its rest (Jaco 0.07°, TALOS's wrists 0.24°, nao_arm and planar2 none).
What it cannot fix: servos whose velocity gain the integrator makes unstable. MuJoCo's Euler integrator applies
an actuator's kv explicitly; where h·kv / M_jj > 2 (h the timestep, M_jj the joint's inertia at the pose) the
joint oscillates at the step rate for good (TALOS's arm_left_3 near a straight elbow: 7; a Panda from its URDF),
whatever the command. Shipped arms use `integrator="implicitfast"` (kv implicit); see bench/pd_baseline.py.
"""

from __future__ import annotations

import mujoco
import numpy as np

from bodyschema.datagen.body.robot import GRAVITY, Robot
from bodyschema.errors import must_be


def holding_torque(model: mujoco.MjModel, q: np.ndarray) -> np.ndarray:
    """τ_hold (N, nv) N·m: what holds each pose q (N, nq) rad at rest, qfrc_bias − qfrc_passive at q̇ = 0."""
    data = mujoco.MjData(model)
    out = np.empty((len(q), model.nv))
    for q_i, out_i in zip(q, out):
        data.qpos[:], data.qvel[:] = q_i, 0.0
        mujoco.mj_fwdPosition(model, data)
        mujoco.mj_fwdVelocity(model, data)                                 # qfrc_bias (RNE), qfrc_passive
        out_i[:] = data.qfrc_bias - data.qfrc_passive
    return out


def servo_dofs(model: mujoco.MjModel, name: str) -> np.ndarray:
    """The dof each actuator drives (nu,), the house error unless each is a servo on one joint of its own."""
    joint = model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT
    dofs = model.jnt_dofadr[model.actuator_trnid[:, 0]]
    if model.nu != model.nv or not joint.all() or len(set(dofs)) != model.nv\
            or (model.actuator_gainprm[:, 0] <= 0).any():
        raise ValueError(must_be(f"robot {name!r}", f"a position servo (gain > 0) on each of its {model.nv} joints "
                                 "for the servo baseline", f"{model.nu} actuators",
                                 "Give the record [actuators] (`bodyschema robot init` infers servos)."))
    return dofs


def servo_targets(robot: Robot, q_target: np.ndarray, gravity: float = GRAVITY) -> np.ndarray:
    """The servo commands (N, nu) that hold the robot at q_target (N, Dq) rad under `gravity` m/s² (the rule of the
    module docstring); the robot's own servos, a private copy of its model."""
    with Robot.load(robot.record, text=robot.source.text, actuators="position", gravity=gravity) as private:
        m = private.model
        dofs = servo_dofs(m, robot.name)
        q = np.asarray(q_target, dtype=np.float64)
        tau = holding_torque(m, q)[:, dofs]                                   # (N, nu) N·m at each servo's joint
        gain, bias = m.actuator_gainprm[:, 0], m.actuator_biasprm              # (nu,), (nu, 10)
        ctrl = (tau / m.actuator_gear[:, 0] - bias[:, 0] - bias[:, 1] * q[:, dofs]) / gain   # (N, nu)
        limited = m.actuator_ctrllimited.astype(bool)                         # where MuJoCo clamps ctrl itself
        low, high = m.actuator_ctrlrange.T
        return np.clip(ctrl, np.where(limited, low, -np.inf), np.where(limited, high, np.inf))
