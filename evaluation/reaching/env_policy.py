"""`AIFPolicy`: the reaching benchmark's AIF controller on a `ReachEnv`, built by reaching's own functions
(`aif_policy`, `aif_goal`, goal inference `goal_pose.imagine`): the goal's pose perceived in imagination first, then
`aif.action.VelocityController` velocity commands, integrated into servo targets (`VelocityPolicy`), into the joint
impedance servo's setpoint (`ImpedancePolicy`, torque robots), or returned as they are (action="velocity").
It lives with the benchmark, not in envs/: the benchmark's agent stands on the env (envs.policies.EpisodePolicy).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from bodyschema.base import modalities
from bodyschema.envs.policies import EpisodePolicy, Sensed
from bodyschema.errors import must_be
from bodyschema.evaluation.core.specs import check_models_match, resolve_encoder, resolve_models
from bodyschema.evaluation.reaching import benchmark, goal_pose
from bodyschema.models.scaling import IMAGE_SCALE


class AIFPolicy(EpisodePolicy):
    """The reaching benchmark's AIF controller on the env. models: specs ("analytic:<robot>:<modality>",
    "models:/<name>@<alias>", a model directory) or SensoryModel objects, of the env's robot; None: the analytic
    models of the goal's modality and the joints. goal_inference: "auto" | "on" | "off" (reaching's);
    goal_starts: starts of the goal-pose search; encoder: an image encoder spec for an image goal's first guess;
    seed: the search's random starts."""

    def __init__(self, env, models: Sequence | None = None, goal_inference: str = "auto", goal_starts: int = 8,
                 encoder: str | None = None, seed: int = 0, tracking_uri: str | None = None):
        super().__init__(env)
        env = self.env
        config = benchmark.ReachingConfig(robot=env.robot_ref, goal=env.goal_modality, goal_inference=goal_inference,
                                          goal_starts=goal_starts, encoder=encoder, seed=seed, mlflow=False,
                                          progress=False, tracking_uri=tracking_uri)
        self.models = _models(models, env, tracking_uri)
        check_models_match(self.models, env.robot)
        names = [m.modality for m in self.models]
        benchmark.goal_modality(config, self.models, env.robot)                  # the goal must be a model's
        if modalities.images_in(names) and not env.image:
            raise ValueError(must_be("the env's image", "True for an image model", env.image,
                                     "Make the env with image=True."))
        self.config = config
        self.infer_pose = benchmark.goal_inference_on(self.config, env.goal_modality, names, env.robot)
        self.encoder = resolve_encoder(encoder, env.robot, tracking_uri) if self.infer_pose else None
        self.rng = np.random.default_rng(seed)
        self.imagined_pose = None

    def start(self, observation, arm: Sensed) -> None:
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

    def act(self, observation, arm: Sensed) -> np.ndarray:
        senses = {m.modality: _reading(m.modality, observation[m.modality]) for m in self.models}
        if self.env.action_kind == "velocity":
            return self.policy.controller.act(senses, self.env.dt)[0]            # (Dq,) rad/s
        return self.policy.command(arm, senses, self.env.dt)[0]


def _reading(modality: str, x: np.ndarray) -> torch.Tensor:
    """An observation as a sensory model reads it: (1, *out) float64, images as intensity in [0, 1]."""
    x = np.asarray(x, dtype=np.float64)
    return torch.from_numpy(x / IMAGE_SCALE if modalities.is_image(modality) else x)[None]


def _models(models: Sequence | None, env, tracking_uri: str | None) -> list:
    """The AIF's models: specs resolved (reaching's resolver), objects as given; None: analytic goal + joints."""
    if models is None:
        models = list(dict.fromkeys(f"analytic:{env.robot_ref}:{m}" for m in (env.goal_modality, "joints")))
    if isinstance(models, (str, bytes)) or not isinstance(models, Sequence) or not models:
        raise ValueError(must_be("models", "a non-empty list of model specs or SensoryModel objects", models))
    specs = [m for m in models if isinstance(m, str)]
    objects = [m for m in models if not isinstance(m, str)]
    return resolve_models(specs, (), tracking_uri) + (resolve_models((), (), None, objects) if objects else [])
