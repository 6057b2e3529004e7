"""The closed reaching loop: B episodes of one robot in the batched simulator (`control.sim.ArmBatch`) at a fixed
control rate.

Per control tick: simulator state → observations (a `Sensing`, e.g. the benchmarks' `core.sensing.Sensors`: the
sensors' units, + Gaussian noise σ, or a stream frozen at its first value) → policy → actuation (servo targets or
torques) → the simulator's control period. Policies wrap a controller into one interface: `reset(arm, goal)`,
`command(arm, observations, dt) -> (B, nu)`, `failed`, `reasons`.
  VelocityPolicy  AIF velocity commands on position servos: ctrl ← clip(ctrl + a·Δt, ctrlrange)   (nao_arm)
  ServoPolicy     baseline on position servos: ctrl = fixed servo commands, the target's joint pose (its true inverse
                  kinematics) + the servo's gravity feed-forward (evaluation/reaching/servo_baseline.py)
  TorquePolicy    torques on motors from a controller with AICController's interface: the AIC (aif/aic.py) or,
                  as baseline, PD + model compensation on the target's joint pose (control/pd.py: the record's tuned
                  gains, else gains from the arm's model and the control period)  (panda, torque arms)
  ImpedancePolicy AIF velocity commands integrated into the setpoint of the arm's joint impedance servo (the
                  same PD + gravity compensation as the baseline, which gets the target pose instead): the panda's
                  counterpart of the nao_arm's position servos  (panda, `--panda-controller velocity`)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch

from bodyschema.control.sim import ArmBatch


class Sensing(Protocol):
    """What the loop reads observations from (the benchmarks' `evaluation.core.sensing.Sensors`): the layer below
    the benchmarks names the interface, not their noise and frozen streams."""

    def read(self, arm: ArmBatch) -> Mapping[str, torch.Tensor]: ...


# ---- policies ---------------------------------------------------------------------------------------------
class VelocityPolicy:
    """AIF velocity commands (aif.action.VelocityController) integrated into the position servos' targets."""

    def __init__(self, controller, goal_precisions: Mapping[str, float] | None = None):
        self.controller, self.goal_precisions = controller, goal_precisions

    def reset(self, arm: ArmBatch, goal: Mapping[str, torch.Tensor]) -> None:
        self.low, self.high = arm.model.actuator_ctrlrange.T
        self.ctrl = np.clip(arm.q, self.low, self.high)
        self.controller.reset(arm.q, goal, self.goal_precisions)

    def command(self, arm: ArmBatch, observations, dt: float) -> np.ndarray:
        velocity = self.controller.act(observations, dt)                   # (B, Dq) rad/s
        self.ctrl = np.clip(self.ctrl + velocity * dt, self.low, self.high)
        return self.ctrl

    failed = property(lambda self: self.controller.failed)
    reasons = property(lambda self: self.controller.reasons)


class TorquePolicy:
    """Torques from a controller with AICController's interface; its joint sensor is the observed "joints" stream
    (the true q when that is not sensed). goal: a fixed goal for this controller (the PD's {"joints": q*})."""

    def __init__(self, controller, goal: Mapping[str, np.ndarray] | None = None):
        self.controller, self.goal = controller, goal

    def reset(self, arm: ArmBatch, goal) -> None:
        self.controller.reset(arm.q, arm.qd, self.goal if self.goal is not None else goal)

    def command(self, arm: ArmBatch, observations, dt: float) -> np.ndarray:
        extra = {k: x for k, x in observations.items() if k != "joints"}
        q = observations["joints"].numpy() if "joints" in observations else arm.q
        return self.controller.act(q, arm.qd, extra, dt)

    failed = property(lambda self: self.controller.failed)
    reasons = property(lambda self: self.controller.reasons)


class ImpedancePolicy:
    """AIF velocity commands (aif.action.VelocityController) integrated into the setpoint of a joint impedance
    servo with AICController's interface (control.pd.PDController): ctrl ← clip(ctrl + a·Δt, joint range)."""

    def __init__(self, controller, servo, limits: tuple[np.ndarray, np.ndarray],
                 goal_precisions: Mapping[str, float] | None = None):
        self.controller, self.servo, self.goal_precisions = controller, servo, goal_precisions
        self.low, self.high = limits                                       # (Dq,) rad

    def reset(self, arm: ArmBatch, goal: Mapping[str, torch.Tensor]) -> None:
        self.ctrl = np.clip(arm.q, self.low, self.high)                    # (B, Dq) rad, the servo setpoint
        self.controller.reset(arm.q, goal, self.goal_precisions)

    def command(self, arm: ArmBatch, observations, dt: float) -> np.ndarray:
        velocity = self.controller.act(observations, dt)                   # (B, Dq) rad/s
        self.ctrl = np.clip(self.ctrl + velocity * dt, self.low, self.high)
        q = observations["joints"].numpy() if "joints" in observations else arm.q
        self.servo.reset(q, arm.qd, {"joints": self.ctrl})                 # K_p (ctrl − q) + K_d (a − q̇) + g(q):
        return self.servo.act(q, arm.qd, dt=dt, qd_ref=velocity)           # setpoint and velocity reference

    failed = property(lambda self: self.controller.failed)
    reasons = property(lambda self: self.controller.reasons)


class ServoPolicy:
    """Baseline on position servos: fixed servo commands, the target's joint pose (true inverse kinematics) with
    its gravity feed-forward (`evaluation.reaching.servo_baseline.servo_targets`), or the bare pose (the old
    baseline)."""

    def __init__(self, q_target: np.ndarray):
        self.q_target = q_target                                           # (B, nu) servo commands (rad)

    def reset(self, arm: ArmBatch, goal) -> None:
        self.failed = np.zeros(len(self.q_target), dtype=bool)
        self.reasons = [None] * len(self.q_target)

    def command(self, arm: ArmBatch, observations, dt: float) -> np.ndarray:
        return self.q_target


# ---- one rollout ------------------------------------------------------------------------------------------
@dataclass
class Rollout:
    t: np.ndarray              # (T+1,) s
    ee_err: np.ndarray         # (T+1, B) m, simulator ee distance to the target's ee
    ee_pixel: np.ndarray       # (T+1, B, 2) px, the ee in the camera image
    q: np.ndarray              # (B, Dq) rad, final joints
    failed: np.ndarray         # (B,) bool
    reasons: list[str | None]


def rollout(robot, policy, q0: np.ndarray, goal: Mapping[str, torch.Tensor], target_xyz: np.ndarray,
            sensors: Sensing, ticks: int, substeps: int, progress: bool = False, desc: str = "") -> Rollout:
    """Run B episodes for `ticks` control periods of substeps·timestep s each, all from rest at q0 (B, Dq)."""
    from tqdm import tqdm
    arm = ArmBatch(robot, q0)
    dt = substeps * robot.model.opt.timestep
    policy.reset(arm, goal)
    errs, pixels = [], []
    for _ in tqdm(range(ticks), desc=desc, disable=not progress, leave=False):
        xyz = arm.ee_xyz
        errs.append(np.linalg.norm(xyz - target_xyz, axis=1))
        pixels.append(robot.project(xyz))
        ctrl = policy.command(arm, sensors.read(arm), dt)
        arm.step(ctrl, substeps)
    xyz = arm.ee_xyz
    errs.append(np.linalg.norm(xyz - target_xyz, axis=1))
    pixels.append(robot.project(xyz))
    failed = arm.failed | np.asarray(policy.failed, dtype=bool)
    reasons = [a or p for a, p in zip(arm.reasons, policy.reasons)]
    return Rollout(np.arange(ticks + 1) * dt, np.array(errs), np.array(pixels), arm.q, failed, reasons)
