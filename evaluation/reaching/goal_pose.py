"""The reaching benchmark's goal inference: every episode's goal is first perceived in imagination
(aif/goal_inference.py), and the AIF controller reaches for that imagined pose through its joints model.

"auto" infers the pose of goals that fix where the end effector is (an image, an ee position); an ee pixel leaves
its depth open, so it keeps its own attractor unless "on" (with a depth cue the cue joins the imagined senses).
Image goals start the search from an image encoder's guess when one is given (`--encoder`). The search of image
goals takes minutes: a progress bar over its starts (`--progress`), and its update and seconds as debug lines.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import torch

from bodyschema.aif.goal_inference import GoalPose, infer_goal_pose
from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.base.modalities import is_image
from bodyschema.datagen.samplers import uniform

MODES = ("auto", "on", "off")
POSE_GOALS = ("ee_xyz",)     # vector goal modalities "auto" infers a pose for, besides every camera's
_log = logging.getLogger(__name__)


def wanted(mode: str, modality: str) -> bool:
    return mode == "on" or (mode == "auto" and (modality in POSE_GOALS or is_image(modality)))


def imagine(config, models, robot, episodes, rng: np.random.Generator, ranges: np.ndarray,
            encoder=None) -> GoalPose:
    """The imagined pose of every episode's goal: perception over the goal's models (the perception's precision
    overrides, and the depth cue's when there is one) from the start pose, the encoder's guess of an image goal
    and random poses of `ranges`."""
    goal_models = [m for m in models if m.modality in episodes.goal]
    given = {**dict(config.perception.precisions), **episodes.extra.get("goal_precisions", {})}
    perception = Perception(goal_models, PerceptionConfig(),     # "auto": the update of perception proper
                            {name: pi for name, pi in given.items() if name in episodes.goal})
    guesses = []
    if encoder is not None and encoder.modality in episodes.goal:
        low, high = robot.sampling_ranges.T
        guesses.append(np.clip(encoder.encode(episodes.goal[encoder.modality]).double().numpy(), low, high))
    n, dq = episodes.q_start.shape
    more = max(config.goal_starts - 1 - len(guesses), 0)
    guesses += list(uniform(rng, ranges, n * more).reshape(more, n, dq))   # start-major: one draw per start
    stacked = torch.from_numpy(np.stack(guesses, axis=1)) if guesses else None   # (N, S−1, Dq) rad
    _log.debug("goal imagination: %s goals of %d episodes from %d starts each (%d guessed by the encoder); "
               "perception method %s (config %s), step control %s", "+".join(episodes.goal), n, 1 + len(guesses),
               int(encoder is not None and encoder.modality in episodes.goal), perception.config.method,
               PerceptionConfig().method, perception.config.flow.step_control)
    start = time.perf_counter()
    pose = infer_goal_pose(perception, episodes.goal, torch.from_numpy(episodes.q_start), stacked,
                           progress=config.progress)
    _log.debug("goal imagination: %.2f s, %d model evaluations", time.perf_counter() - start, pose.evaluations)
    return pose


def imagined_error_mm(robot, episodes, pose: GoalPose) -> np.ndarray:
    """The imagined pose's ee distance from the target's ee: what imagination got wrong before any movement. (N,)"""
    lim = robot.joint_limits
    q = np.clip(pose.q.numpy(), lim[:, 0], lim[:, 1])
    return 1e3 * np.linalg.norm(robot.fk(q) - episodes.target_xyz, axis=1)
