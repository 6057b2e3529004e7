"""The streams of the agency benchmark: what the robot commanded, what it predicted, what it felt and saw.

Per episode the arm starts at rest at q0 and a movement is made: position-servo targets held for random durations
(babbling), simulated by the core's ArmBatch. Per episode kind,
  self         the robot commanded that movement: it feels and sees it;
  pushed       the same movement imposed from outside (an external hand moves the arm) while the robot commanded
               to hold still: it feels and sees the movement;
  scene_moved  the robot commanded to hold still and did (its joints feel stillness) while the scene moved in front
               of the camera as the hand would have: it sees the movement.
Forward model (efference copy): the robot predicts the consequence of its own command with its dynamics (the same
ArmBatch), started from its first joint reading. Sensory delay d: every stream arrives d late (before the start
the arm rested at q0), the prediction is for now. Every episode draws from its own generators, so an episode's
movement and noise do not depend on how many episodes there are.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bodyschema.base.modalities import is_image
from bodyschema.control.sim import ArmBatch, control_substeps
from bodyschema.evaluation.core.seeds import EVAL_STREAM
from bodyschema.evaluation.core.sensing import sense

SELF = "self"
ALL = "all senses"                       # the comparison on every sense at once (report and plots)
SOURCES = ("pushed", "scene_moved")
STREAM_WORD = 0xA6E7                     # second entropy word: agency episodes
ROLE = {"start": 0, "commands": 1, "proprio_noise": 2, "visual_noise": 3}


@dataclass
class Episodes:
    kind: np.ndarray                     # (N,) str: "self" or a source
    rest: np.ndarray                     # (N, Dq) rad, the pose the arm rested at before the episode
    predicted: np.ndarray                # (N, T, Dq) rad, the forward model's pose from the own command
    felt: np.ndarray                     # (N, T, Dq) rad, the arm's true pose (before delay and noise)
    seen: np.ndarray                     # (N, T, Dq) rad, the pose the camera shows (before delay and noise)
    failed: np.ndarray                   # (N,) bool, a simulation that diverged


def episode_rng(seed: int, episode: int, role: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([EVAL_STREAM, STREAM_WORD, int(seed), int(episode),
                                                         ROLE[role]]))


def episode_kinds(n: int, sources: Sequence[str]) -> np.ndarray:
    """n // 2 self episodes, the rest split as evenly as possible over the sources (first ones get the extra)."""
    others = n - n // 2
    counts = [others // len(sources) + (i < others % len(sources)) for i in range(len(sources))]
    return np.array([SELF] * (n // 2) + [k for k, c in zip(sources, counts) for _ in range(c)])


def commands(rng: np.random.Generator, q0: np.ndarray, ranges: np.ndarray, steps: int, period: float,
             hold_s: tuple[float, float]) -> np.ndarray:
    """(T, Dq) rad servo targets: random poses in `ranges`, each held for U(hold_s) s (whole frames)."""
    out, f = np.empty((steps, len(q0))), 0
    while f < steps:
        hold = max(1, round(rng.uniform(*hold_s) / period))
        out[f:f + hold] = rng.uniform(ranges[:, 0], ranges[:, 1])
        f += hold
    return out


def simulate(robot, q0: np.ndarray, ctrl: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """(poses (B, T, Dq) rad after each control period, failed (B,)) of B arms from q0 (B, Dq) under ctrl (B, T, Dq)."""
    substeps = control_substeps(1.0 / period, robot.model.opt.timestep, "period")
    arm = ArmBatch(robot, q0)
    poses = np.empty(ctrl.shape)
    for f in range(ctrl.shape[1]):
        arm.step(ctrl[:, f], substeps)
        poses[:, f] = arm.q
    return poses, arm.failed.copy()


def make_episodes(config, robot, proprio0_noise: np.ndarray) -> Episodes:
    """Every episode's movement, hold and forward-model prediction (one ArmBatch of 3N arms). config: an
    AgencyConfig; proprio0_noise (N, Dq) rad: the noise of the first joint reading the prediction starts from."""
    n, t, ranges = config.trials, config.steps, robot.sampling_ranges
    kinds = episode_kinds(n, config.sources)
    q0 = np.stack([episode_rng(config.seed, i, "start").uniform(ranges[:, 0], ranges[:, 1]) for i in range(n)])
    move = np.stack([commands(episode_rng(config.seed, i, "commands"), q0[i], ranges, t, config.period,
                              config.hold_s) for i in range(n)])                       # (N, T, Dq) rad
    hold = np.repeat(q0[:, None, :], t, axis=1)                                         # (N, T, Dq) rad
    own = np.where((kinds == SELF)[:, None, None], move, hold)                          # what the robot commanded
    start = np.clip(q0 + proprio0_noise, robot.joint_limits[:, 0], robot.joint_limits[:, 1])
    poses, failed = simulate(robot, np.concatenate([q0, q0, start]), np.concatenate([move, hold, own]),
                             config.period)
    moved, held, predicted = poses[:n], poses[n:2 * n], poses[2 * n:]
    felt = np.where((kinds == "scene_moved")[:, None, None], held, moved)
    return Episodes(kinds, q0, predicted, felt, moved, failed[:n] | failed[n:2 * n] | failed[2 * n:])


def delayed(x: np.ndarray, rest: np.ndarray, lag: int) -> np.ndarray:
    """x (N, T, ...) seen `lag` frames late; before the start, the resting value rest (N, ...)."""
    if lag == 0:
        return x
    return np.concatenate([np.repeat(rest[:, None], lag, axis=1), x[:, :-lag]], axis=1)


def observe(robot, modalities: Sequence[str], episodes: Episodes, lag: int,
            noise: dict[str, float], seed: int) -> dict[str, np.ndarray]:
    """modality → (N, T, *out): the joints feel `felt`, the visual modalities see `seen`, `lag` frames late, plus
    noise σ drawn per episode from its own generator (the same draws at every delay)."""
    n, t, dq = episodes.felt.shape
    out = {}
    for m in modalities:
        source = episodes.felt if m == "joints" else episodes.seen
        q = delayed(source, episodes.rest, lag).reshape(n * t, dq)
        x = np.asarray(sense(robot, m, q, image_dtype=np.float32))
        x = x.reshape(n, t, *x.shape[1:]).astype(np.float32 if is_image(m) else np.float64)
        sigma = noise.get(m, 0.0)
        if sigma > 0:
            role = "proprio_noise" if m == "joints" else "visual_noise"
            x = x + sigma * np.stack([episode_rng(seed, i, role).standard_normal(x.shape[1:]) for i in range(n)])
        out[m] = np.clip(x, 0.0, 1.0) if is_image(m) else x
    return out
