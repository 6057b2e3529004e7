"""The closed reaching loop: B MuJoCo episodes of one robot stepped in lockstep at a fixed control rate.

Per control tick: simulator state → observations (the sensors' units, + Gaussian noise σ, or a stream frozen at
its first value) → policy → actuation (servo targets or torques) → `mj_step` × substeps → `mj_forward`, so
site positions and bias forces always belong to the current state. Policies wrap a controller into one
interface: `reset(arm, goal)`, `command(arm, observations, dt) -> (B, nu)`, `failed`, `reasons`.
  VelocityPolicy  AIF velocity commands on position servos: ctrl ← clip(ctrl + a·Δt, ctrlrange)   (nao_arm)
  ServoPolicy     baseline on position servos: ctrl = the target's joint pose (its true inverse kinematics)
  TorquePolicy    torques on motors from a controller with AICController's interface: the AIC (aif/aic.py) or,
                  as baseline, PD + gravity compensation on the target's joint pose (evaluation/pd.py)  (panda)
An episode whose simulation goes non-finite or trips MuJoCo's bad-acceleration warning is marked failed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import mujoco
import numpy as np
import torch

from bodyschema.errors import must_be
from bodyschema.models.scaling import IMAGE_SCALE

SENSED = ("joints", "ee_xyz", "ee_pixel", "image")


def control_substeps(control_hz: float, timestep: float, name: str = "control_hz") -> int:
    """MuJoCo steps per control period; the house error (about the config field `name`) unless the period is a
    whole number of steps. Shared by every closed-loop benchmark."""
    ok = isinstance(control_hz, (int, float)) and np.isfinite(control_hz) and control_hz > 0
    ratio = 1.0 / (control_hz * timestep) if ok else float("nan")
    n = int(round(ratio)) if ok else 0
    if n < 1 or abs(ratio - n) > 1e-6 * n:
        rates = ", ".join(f"{1.0 / (k * timestep):g}" for k in (1, 2, 5, 10, 20))
        raise ValueError(must_be(name, f"a rate whose period is a whole number of MuJoCo steps of "
                                 f"{timestep * 1e3:g} ms", control_hz, f"Use e.g. {rates} Hz."))
    return n


class ArmBatch:
    """B copies of the robot's dynamics (one MjData each) started at rest at q0 (B, Dq) rad."""

    def __init__(self, robot, q0: np.ndarray):
        self.robot, self.model = robot, robot.model
        self.position = bool(np.all(robot.model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE))
        self.datas = []
        for q in q0:
            d = mujoco.MjData(self.model)
            d.qpos[:] = q
            d.ctrl[:] = q if self.position else 0.0                       # servos hold the start pose
            mujoco.mj_forward(self.model, d)
            self.datas.append(d)
        self.failed = np.zeros(len(q0), dtype=bool)
        self.reasons: list[str | None] = [None] * len(q0)
        self._site = self.model.site("ee").id

    @property
    def q(self) -> np.ndarray:
        return np.array([d.qpos for d in self.datas])                     # (B, Dq) rad

    @property
    def qd(self) -> np.ndarray:
        return np.array([d.qvel for d in self.datas])                     # (B, Dq) rad/s

    @property
    def ee_xyz(self) -> np.ndarray:
        return np.array([d.site_xpos[self._site] for d in self.datas])    # (B, 3) m

    @property
    def bias(self) -> np.ndarray:
        return np.array([d.qfrc_bias for d in self.datas])                # (B, Dq) N·m, gravity + Coriolis

    def step(self, ctrl: np.ndarray, substeps: int) -> None:
        """Apply ctrl (B, nu) for `substeps` MuJoCo steps; episodes already failed stay frozen."""
        for i, d in enumerate(self.datas):
            if self.failed[i]:
                continue
            qpos, qvel = d.qpos.copy(), d.qvel.copy()
            d.ctrl[:] = ctrl[i]
            for _ in range(substeps):
                mujoco.mj_step(self.model, d)
            if not np.isfinite(d.qpos).all() or d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
                self.failed[i], self.reasons[i] = True, "simulation diverged (bad acceleration)"
                d.qpos[:], d.qvel[:] = qpos, qvel                         # freeze at the last finite state
            mujoco.mj_forward(self.model, d)


@dataclass
class Sensors:
    """What the controller senses: noise σ per modality (its units: rad, m, px, intensity), frozen streams."""

    modalities: tuple[str, ...]
    noise: Mapping[str, float] = field(default_factory=dict)
    frozen: frozenset[str] = frozenset()
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    _held: dict = field(default_factory=dict)

    def read(self, arm: ArmBatch) -> dict[str, torch.Tensor]:
        q, xyz, robot = arm.q, arm.ee_xyz, arm.robot
        out = {}
        for name in self.modalities:
            if name in self._held:
                out[name] = self._held[name]
                continue
            if name == "joints":
                x = q
            elif name == "ee_xyz":
                x = xyz
            elif name == "ee_pixel":
                x = robot.project(xyz)
            else:                                                          # image, in the models' [0, 1] scale
                lim = robot.joint_limits
                x = robot.render(np.clip(q, lim[:, 0], lim[:, 1])).astype(np.float64) / IMAGE_SCALE
            sigma = self.noise.get(name, 0.0)
            if sigma > 0:
                x = x + sigma * self.rng.standard_normal(x.shape)
                if name == "image":
                    x = np.clip(x, 0.0, 1.0)
            out[name] = torch.from_numpy(np.asarray(x, dtype=np.float64))
            if name in self.frozen:
                self._held[name] = out[name]
        return out


# ---- policies ---------------------------------------------------------------------------------------------
class VelocityPolicy:
    """AIF velocity commands (aif.action.VelocityController) integrated into the position servos' targets."""

    def __init__(self, controller):
        self.controller = controller

    def reset(self, arm: ArmBatch, goal: Mapping[str, torch.Tensor]) -> None:
        self.low, self.high = arm.model.actuator_ctrlrange.T
        self.ctrl = np.clip(arm.q, self.low, self.high)
        self.controller.reset(arm.q, goal)

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


class ServoPolicy:
    """Baseline on position servos: the target's joint pose (true inverse kinematics) as the servo target."""

    def __init__(self, q_target: np.ndarray):
        self.q_target = q_target                                           # (B, Dq) rad

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
            sensors: Sensors, ticks: int, substeps: int, progress: bool = False, desc: str = "") -> Rollout:
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
