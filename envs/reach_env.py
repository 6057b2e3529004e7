"""`ReachEnv`: one simulated arm reaching for a goal, as a Gymnasium environment (reaching's episode, one at a time).

The arm is the control layer's simulator (`control.sim.ArmBatch`, a batch of one) at the robot record's reaching
control rate and duration ([reaching] control_hz, duration_s). `reset(seed=...)` draws, from `np_random`, a goal pose
the camera sees (`control.targets.in_view_targets`) and a start pose uniform in the robot's sampling ranges; the
arm starts there at rest. The goal is what the goal sensor reads at the goal pose (the env's own sensors, `_SENSORS`,
as reaching's `goals.make_goal` reads it): reachable by construction. `options={"target": q, "start": q}`
(rad, (Dq,)) set either pose instead.
Actions (`action=`): "position" servo targets (servo robots), "torque" motor torques (torque robots), or "velocity"
joint velocity commands, integrated into the servo targets (servos) or into the setpoint of the joint impedance
servo (torque robots: PD + gravity compensation), the way reaching integrates the AIF's commands
(`control.loop.VelocityPolicy` / `ImpedancePolicy`, which do it here too).
Reward: −ee distance to the goal pose's ee (m). Terminated: within `success_mm` and resting (ee slower than
REST_M_S), or the simulation diverged (info["failure"]); truncated at the duration. Joint velocities are not
observed (the simulator bounds them nowhere): a torque policy differences the joints (`policies.py`).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from bodyschema.aif.action import ActionConfig
from bodyschema.control.loop import ImpedancePolicy, VelocityPolicy
from bodyschema.control.pd import PDController
from bodyschema.control.robot_defaults import reaching_defaults
from bodyschema.control.sim import ArmBatch, control_substeps
from bodyschema.control.targets import in_view_targets
from bodyschema.datagen.body.record import check_robot_ref
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.samplers import uniform
from bodyschema.envs import spaces as env_spaces
from bodyschema.errors import must_be

REST_M_S = 0.01     # m/s: an ee slower than this within success_mm stays there (it would take 1 s to leave 1 cm)

# What each sensor reads with the arm at q (Dq,) rad and its ee at xyz (3,) m, in observation units (the image uint8),
# in the observation's key order; the goal is the goal modality's reading at the goal pose.
_SENSORS = {"joints": lambda robot, q, xyz: q, "ee_xyz": lambda robot, q, xyz: xyz,
            "ee_pixel": lambda robot, q, xyz: robot.project(xyz[None])[0],
            "image": lambda robot, q, xyz: robot.render(q[None], check=False)[0]}


class _Commanded:
    """The controller interface of `VelocityController` (reset / act / failed / reasons) answering with the env's
    velocity action, so reaching's own policies integrate it into servo targets or impedance setpoints."""

    def __init__(self):
        self.velocity = np.zeros((1, 0))                                    # (1, Dq) rad/s, the latest action
        self.failed, self.reasons = np.zeros(1, dtype=bool), [None]

    def reset(self, belief, goal, goal_precisions=None) -> None:
        self.velocity = np.zeros_like(np.asarray(belief, dtype=np.float64))   # (1, Dq) rad/s

    def act(self, observations, dt: float) -> np.ndarray:
        return self.velocity


class ReachEnv(gym.Env):
    """A robot arm reaching for a goal. robot: "nao_arm" | "planar2" | "panda" | an MJCF/URDF/record file; goal:
    "ee_xyz" | "ee_pixel" | "joints" | "image"; action: "auto" (the robot's actuators: servo targets or torques) |
    "position" | "torque" | "velocity"; image: add the camera image to the observation; image_size: (H, W) px
    (None: the record's); success_mm: mm; duration: s per episode (None: the record's [reaching] duration_s)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, robot: str | Path = "nao_arm", goal: str = "ee_xyz", action: str = "auto", image: bool = False,
                 image_size: tuple[int, int] | None = None, success_mm: float = 10.0, duration: float | None = None,
                 render_mode: str | None = None):
        _check_arguments(robot, goal, action, image, success_mm, duration, render_mode)
        defaults = reaching_defaults(str(robot))
        self.robot_ref, self.goal_modality, self.image, self.success_mm = str(robot), goal, bool(image), success_mm
        self.robot = Robot.load(self.robot_ref, image_size=image_size, actuators=defaults.actuators)
        self.action_kind = _action_kind(action, self.robot.actuation)
        self.control_hz, self.duration = defaults.control_hz, defaults.duration_s if duration is None else duration
        self.substeps = control_substeps(self.control_hz, self.robot.model.opt.timestep)
        self.dt = self.substeps * self.robot.model.opt.timestep                    # s, one control period
        self.max_steps = int(round(self.duration * self.control_hz))
        self.max_velocity = (defaults.action or ActionConfig()).max_velocity      # rad/s, velocity actions
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.control_hz}
        self.observation_space = env_spaces.observation_space(self.robot, goal, self.image)
        self.native_action_space = env_spaces.action_space(self.robot, self.action_kind, self.max_velocity)
        self.action_space = env_spaces.normalized_space(self.native_action_space)   # float32 [-1, 1]
        self.episode = -1            # counts resets: a policy bound to the env sees a new episode begin
        self.arm = None

    # ---- the Gymnasium API --------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"target", "start"})
        if unknown:
            raise ValueError(must_be("reset options", "keys among 'target' and 'start' (joint poses, rad)", unknown))
        q_target = self._pose(options, "target") if "target" in options else \
            in_view_targets(self.np_random, self.robot, 1)                        # (1, Dq) rad
        q_start = self._pose(options, "start") if "start" in options else \
            uniform(self.np_random, self.robot.sampling_ranges, 1)                # (1, Dq) rad
        self.goal_pose, self.goal_xyz = q_target, self.robot.fk(q_target)        # (1, Dq) rad, (1, 3) m
        self._goal = _SENSORS[self.goal_modality](self.robot, q_target[0], self.goal_xyz[0])
        self.arm = ArmBatch(self.robot, q_start)
        self._integrator = self._velocity_integrator()
        self.steps, self.episode = 0, self.episode + 1
        return self._observation(), self._info()

    def step(self, action):
        if self.arm is None:
            raise RuntimeError("ReachEnv.step before reset: call env.reset(seed=...) first.")
        ctrl = self._ctrl(self._check_action(action))                            # (1, nu)
        self.arm.step(ctrl, self.substeps)
        self.steps += 1
        info = self._info()
        resting = self.ee_speed() < REST_M_S
        terminated = bool(self.arm.failed[0] or (info["success"] and resting))
        truncated = bool(not terminated and self.steps >= self.max_steps)
        return self._observation(), -info["ee_error_mm"] / 1e3, terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array" or self.arm is None:
            return None
        frame = self.robot.render(self._joints()[None])[0]                        # (H, W[, 3]) uint8
        return frame if frame.ndim == 3 else np.repeat(frame[..., None], 3, axis=2)

    def close(self):
        self.robot.close()

    # ---- state --------------------------------------------------------------------------------------------
    def ee_error_mm(self) -> float:
        return float(1e3 * np.linalg.norm(self.arm.ee_xyz[0] - self.goal_xyz[0]))

    def ee_speed(self) -> float:
        """m/s, |J(q) q̇| of the simulated arm."""
        jac = self.robot.jacobian(self.arm.q, check=False)[0]                     # (3, Dq) m/rad
        return float(np.linalg.norm(jac @ self.arm.qd[0]))

    def _joints(self) -> np.ndarray:
        return env_spaces.clip_to(self.observation_space["joints"], self.arm.q[0])  # (Dq,) rad

    def _observation(self) -> dict[str, np.ndarray]:
        space, q = self.observation_space, self._joints()
        xyz = self.arm.ee_xyz[0]                                                  # (3,) m
        obs = {k: env_spaces.clip_to(space[k], sensor(self.robot, q, xyz)) for k, sensor in _SENSORS.items()
               if k in space.spaces}
        obs["goal"] = env_spaces.clip_to(space["goal"], self._goal)
        return obs

    def _info(self) -> dict:
        error = self.ee_error_mm()
        info = {"ee_error_mm": error, "success": bool(error < self.success_mm)}
        if self.arm.failed[0]:
            info["failure"] = self.arm.reasons[0]
        return info

    # ---- actions ------------------------------------------------------------------------------------------
    def _velocity_integrator(self):
        """Reaching's own integration of velocity commands (servo targets / impedance setpoint), or None."""
        if self.action_kind != "velocity":
            return None
        integrator = VelocityPolicy(_Commanded()) if self.robot.actuation == "position" else \
            ImpedancePolicy(_Commanded(), PDController(self.robot), tuple(self.robot.joint_limits.T))
        integrator.reset(self.arm, {})
        return integrator

    def to_native(self, action) -> np.ndarray:
        """(nu,) in [-1, 1] → the native command (rad, N·m or rad/s) in `native_action_space`."""
        return env_spaces.to_native(self.native_action_space, action)

    def to_action(self, command) -> np.ndarray:
        """A native command (clipped into `native_action_space`) → the float32 action in [-1, 1] that gives it."""
        return env_spaces.to_normalized(self.native_action_space, command)

    def _ctrl(self, action: np.ndarray) -> np.ndarray:
        action = self.to_native(action)[None]                                      # (1, nu) native, clipped
        if self._integrator is None:
            return action
        self._integrator.controller.velocity = action
        return self._integrator.command(self.arm, {}, self.dt)

    def _check_action(self, action) -> np.ndarray:
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != self.action_space.shape or not np.isfinite(a).all():
            raise ValueError(must_be("action", f"a finite array of shape {self.action_space.shape} "
                                     f"({self.action_kind})", getattr(a, "shape", action)))
        return a

    def _pose(self, options: dict, key: str) -> np.ndarray:
        q = np.asarray(options[key], dtype=np.float64).reshape(1, -1)
        return self.robot.check_q(q)


def _action_kind(action: str, actuation: str) -> str:
    if action == "auto":
        return actuation
    if action != "velocity" and action != actuation:
        raise ValueError(must_be("action", f"'auto', 'velocity' or '{actuation}' for this robot's {actuation} "
                                 "actuators", action, "Servo robots take position targets, torque robots torques."))
    return action


def _check_arguments(robot, goal, action, image, success_mm, duration, render_mode) -> None:
    problem = check_robot_ref(robot)
    if problem:
        raise ValueError(problem)
    if goal not in env_spaces.GOALS:
        raise ValueError(must_be("goal", f"one of {env_spaces.GOALS}", goal))
    if action not in ("auto", *env_spaces.ACTIONS):
        raise ValueError(must_be("action", f"'auto' or one of {env_spaces.ACTIONS}", action))
    if not isinstance(image, bool):
        raise ValueError(must_be("image", "True or False (add the camera image to the observation)", image))
    for name, value, unit in (("success_mm", success_mm, "mm"), ("duration", duration, "s")):
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not (value is None and name == "duration") and not (number and np.isfinite(value) and value > 0):
            raise ValueError(must_be(name, f"a finite number > 0 ({unit})", value))
    if render_mode not in (None, "rgb_array"):
        raise ValueError(must_be("render_mode", "None or 'rgb_array' (the robot camera's image)", render_mode))
