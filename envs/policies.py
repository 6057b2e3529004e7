"""Policies on a `ReachEnv`, each `policy(observation) -> action`: the project's controllers and a random baseline.

    AIFPolicy     the reaching benchmark's AIF controller, built by reaching's own functions (`aif_policy`,
                  `aif_goal`, goal inference `goal_pose.imagine`): the goal's pose perceived in imagination first,
                  then `aif.action.VelocityController` velocity commands, integrated into servo targets
                  (`VelocityPolicy`), into the joint impedance servo's setpoint (`ImpedancePolicy`, torque robots),
                  or returned as they are (action="velocity")
    PDPolicy      reaching's baseline: the servos commanded to the goal's true inverse kinematics (`ServoPolicy`), or
                  PD + gravity compensation on it (`TorquePolicy(PDController)`, torque robots). It reads the goal
                  pose from the env: privileged, as in the benchmark
    RandomPolicy  uniform samples of the action space
A policy bound to an env notices a new episode by the env's reset counter (`env.episode`). Reaching's policies read
an arm's q and q̇: here q is the observed joints and q̇ their difference over one control period (zero at the
start, at rest). With the torque robots' one MuJoCo step per period that difference is the simulator's q̇ exactly
(position integrates the new velocity).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np
import torch

from bodyschema.errors import must_be


class _Sensed:
    """What reaching's policies read of an `ArmBatch` (q, q̇, the model), here from observations: a batch of one."""

    def __init__(self, model, q: np.ndarray, qd: np.ndarray):
        self.model, self.q, self.qd = model, q[None], qd[None]              # (1, Dq) rad, rad/s


class _EpisodePolicy:
    """A policy bound to one env: `start` at each new episode, `act` every step, both on the sensed arm."""

    def __init__(self, env):
        self.env = env.unwrapped
        self._episode, self._q_prev = None, None

    def __call__(self, observation) -> np.ndarray:
        q = np.asarray(observation["joints"], dtype=np.float64)
        new = self._episode != self.env.episode
        qd = np.zeros_like(q) if new else (q - self._q_prev) / self.env.dt   # rad/s
        arm = _Sensed(self.env.robot.model, q, qd)
        self._q_prev = q
        if new:
            self._episode = self.env.episode
            self.start(observation, arm)
        command = np.asarray(self.act(observation, arm), dtype=np.float64).reshape(self.env.action_space.shape)
        return self.env.to_action(command)                    # native (clipped into its box) → float32 [-1, 1]

    def start(self, observation, arm: _Sensed) -> None:
        raise NotImplementedError

    def act(self, observation, arm: _Sensed) -> np.ndarray:
        raise NotImplementedError


class RandomPolicy:
    """Uniform random actions, seeded (the env's action space is copied: its own seed stays the env's)."""

    def __init__(self, env, seed: int = 0):
        self.space = copy.deepcopy(env.action_space)
        self.space.seed(seed)

    def __call__(self, observation) -> np.ndarray:
        return self.space.sample()


class PDPolicy(_EpisodePolicy):
    """Reaching's PD baseline on the env's own actuators (position targets or torques)."""

    def __init__(self, env):
        super().__init__(env)
        if self.env.action_kind == "velocity":
            raise ValueError(must_be("the env's action", "'position' or 'torque' for PDPolicy (it commands servo "
                                     "targets or torques)", "velocity", "Make the env with action='auto'."))
        if self.env.action_kind == "torque":
            from bodyschema.evaluation.core.pd import PDController
            self._pd = PDController(self.env.robot)

    def start(self, observation, arm: _Sensed) -> None:
        from bodyschema.evaluation.reaching.loop import ServoPolicy, TorquePolicy
        target = self.env.goal_pose.copy()                                       # (1, Dq) rad, the true IK
        self.policy = ServoPolicy(target) if self.env.action_kind == "position" else \
            TorquePolicy(self._pd, goal={"joints": target})
        self.policy.reset(arm, {})

    def act(self, observation, arm: _Sensed) -> np.ndarray:
        return self.policy.command(arm, {}, self.env.dt)[0]


class AIFPolicy(_EpisodePolicy):
    """The reaching benchmark's AIF controller on the env. models: specs ("analytic:<robot>:<modality>",
    "models:/<name>@<alias>", a model directory) or SensoryModel objects, of the env's robot; None: the analytic
    models of the goal's modality and the joints. goal_inference: "auto" | "on" | "off" (reaching's);
    goal_starts: starts of the goal-pose search; encoder: an image encoder spec for an image goal's first guess;
    seed: the search's random starts."""

    def __init__(self, env, models: Sequence | None = None, goal_inference: str = "auto", goal_starts: int = 8,
                 encoder: str | None = None, seed: int = 0, tracking_uri: str | None = None):
        super().__init__(env)
        from bodyschema.evaluation.core.specs import check_models_match, resolve_encoder
        from bodyschema.evaluation.reaching import benchmark
        env = self.env
        config = benchmark.ReachingConfig(robot=env.robot_ref, goal=env.goal_modality, goal_inference=goal_inference,
                                          goal_starts=goal_starts, encoder=encoder, seed=seed, mlflow=False,
                                          progress=False, tracking_uri=tracking_uri)
        self.models = _models(models, env, tracking_uri)
        check_models_match(self.models, env.robot)
        names = [m.modality for m in self.models]
        benchmark.goal_modality(config, self.models, env.robot)                  # the goal must be a model's
        if "image" in names and not env.image:
            raise ValueError(must_be("the env's image", "True for an image model", env.image,
                                     "Make the env with image=True."))
        self.config = config
        self.infer_pose = benchmark.goal_inference_on(self.config, env.goal_modality, names, env.robot)
        self.encoder = resolve_encoder(encoder, env.robot, tracking_uri) if self.infer_pose else None
        self.rng = np.random.default_rng(seed)
        self.imagined_pose = None

    def start(self, observation, arm: _Sensed) -> None:
        from bodyschema.evaluation.reaching import benchmark, goal_pose
        env = self.env
        goal = {env.goal_modality: _reading(env.goal_modality, observation["goal"])}
        unknown = np.full_like(arm.q, np.nan)                 # the target pose and ee: not the AIF's to know
        episodes = benchmark.Episodes(unknown, arm.q.copy(), goal, unknown[:, :3])
        if self.infer_pose:
            episodes.extra["imagined"] = goal_pose.imagine(self.config, self.models, env.robot, episodes, self.rng,
                                                           env.robot.sampling_ranges, self.encoder)
            self.imagined_pose = episodes.extra["imagined"].q.numpy()[0]        # (Dq,) rad
        goals, precisions = benchmark.aif_goal(self.config, self.models, episodes)
        self.policy = benchmark.aif_policy(self.config, self.models, env.robot, precisions)
        self.policy.reset(arm, goals)

    def act(self, observation, arm: _Sensed) -> np.ndarray:
        senses = {m.modality: _reading(m.modality, observation[m.modality]) for m in self.models}
        if self.env.action_kind == "velocity":
            return self.policy.controller.act(senses, self.env.dt)[0]            # (Dq,) rad/s
        return self.policy.command(arm, senses, self.env.dt)[0]


def _reading(modality: str, x: np.ndarray) -> torch.Tensor:
    """An observation as a sensory model reads it: (1, *out) float64, images as intensity in [0, 1]."""
    from bodyschema.models.scaling import IMAGE_SCALE
    x = np.asarray(x, dtype=np.float64)
    return torch.from_numpy(x / IMAGE_SCALE if modality == "image" else x)[None]


def _models(models: Sequence | None, env, tracking_uri: str | None) -> list:
    """The AIF's models: specs resolved (reaching's resolver), objects as given; None: analytic goal + joints."""
    from bodyschema.evaluation.core.specs import resolve_models
    if models is None:
        models = list(dict.fromkeys(f"analytic:{env.robot_ref}:{m}" for m in (env.goal_modality, "joints")))
    if isinstance(models, (str, bytes)) or not isinstance(models, Sequence) or not models:
        raise ValueError(must_be("models", "a non-empty list of model specs or SensoryModel objects", models))
    specs = [m for m in models if isinstance(m, str)]
    objects = [m for m in models if not isinstance(m, str)]
    return resolve_models(specs, (), tracking_uri) + (resolve_models((), (), None, objects) if objects else [])
