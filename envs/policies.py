"""Policies on a `ReachEnv`, each `policy(observation) -> action`: the PD baseline and a random one.

    PDPolicy      reaching's baseline: the servos commanded to the goal's true inverse kinematics (`ServoPolicy`), or
                  PD + gravity compensation on it (`TorquePolicy(PDController)`, torque robots). It reads the goal
                  pose from the env: privileged, as in the benchmark
    RandomPolicy  uniform samples of the action space
The reaching benchmark's AIF controller on an env is `evaluation.reaching.AIFPolicy` (an `EpisodePolicy` too): a
benchmark's agent stands on the env, the env never on a benchmark.
A policy bound to an env notices a new episode by the env's reset counter (`env.episode`). Reaching's policies read
an arm's q and q̇: here q is the observed joints and q̇ their difference over one control period (zero at the
start, at rest). With the torque robots' one MuJoCo step per period that difference is the simulator's q̇ exactly
(position integrates the new velocity).
"""

from __future__ import annotations

import copy

import numpy as np

from bodyschema.control.loop import ServoPolicy, TorquePolicy
from bodyschema.control.pd import PDController
from bodyschema.errors import must_be


class Sensed:
    """What reaching's policies read of an `ArmBatch` (q, q̇, the model), here from observations: a batch of one."""

    def __init__(self, model, q: np.ndarray, qd: np.ndarray):
        self.model, self.q, self.qd = model, q[None], qd[None]              # (1, Dq) rad, rad/s


class EpisodePolicy:
    """A policy bound to one env: `start` at each new episode, `act` every step, both on the sensed arm."""

    def __init__(self, env):
        self.env = env.unwrapped
        self._episode, self._q_prev = None, None

    def __call__(self, observation) -> np.ndarray:
        q = np.asarray(observation["joints"], dtype=np.float64)
        new = self._episode != self.env.episode
        qd = np.zeros_like(q) if new else (q - self._q_prev) / self.env.dt   # rad/s
        arm = Sensed(self.env.robot.model, q, qd)
        self._q_prev = q
        if new:
            self._episode = self.env.episode
            self.start(observation, arm)
        command = np.asarray(self.act(observation, arm), dtype=np.float64).reshape(self.env.action_space.shape)
        return self.env.to_action(command)                    # native (clipped into its box) → float32 [-1, 1]

    def start(self, observation, arm: Sensed) -> None:
        raise NotImplementedError

    def act(self, observation, arm: Sensed) -> np.ndarray:
        raise NotImplementedError


class RandomPolicy:
    """Uniform random actions, seeded (the env's action space is copied: its own seed stays the env's)."""

    def __init__(self, env, seed: int = 0):
        self.space = copy.deepcopy(env.action_space)
        self.space.seed(seed)

    def __call__(self, observation) -> np.ndarray:
        return self.space.sample()


class PDPolicy(EpisodePolicy):
    """Reaching's PD baseline on the env's own actuators (position targets or torques)."""

    def __init__(self, env):
        super().__init__(env)
        if self.env.action_kind == "velocity":
            raise ValueError(must_be("the env's action", "'position' or 'torque' for PDPolicy (it commands servo "
                                     "targets or torques)", "velocity", "Make the env with action='auto'."))
        if self.env.action_kind == "torque":
            self._pd = PDController(self.env.robot)

    def start(self, observation, arm: Sensed) -> None:
        target = self.env.goal_pose.copy()                                       # (1, Dq) rad, the true IK
        self.policy = ServoPolicy(target) if self.env.action_kind == "position" else \
            TorquePolicy(self._pd, goal={"joints": target})
        self.policy.reset(arm, {})

    def act(self, observation, arm: Sensed) -> np.ndarray:
        return self.policy.command(arm, {}, self.env.dt)[0]
