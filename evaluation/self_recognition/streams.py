"""The streams of the self-recognition benchmark: what the babbling robot feels and what its camera sees.

Every episode the robot babbles (datagen's `Babbler`: position servos tracking random joint targets held for
random durations, under gravity), clipped to the sampling ranges (the box the models know). Proprioception is
q(t) + noise; the visual stream shows, per episode kind,
  self        its own body, q(t);
  second_arm  another arm of the same kind babbling with its own commands, q'(t);
  delayed     its own body seen late, q(t − delay) (the babbling starts `delay` early);
  mirrored    its own body in a mirror: images flipped left-right, ee_pixel u → W − 1 − u, ee_xyz reflected
              through the camera's vertical plane (the same mirror in 3-D: the principal point is centred).
Every episode draws from its own generators (`SeedSequence([EVAL_STREAM, STREAM_WORD, seed, episode, role])`),
so an episode's streams do not depend on how many episodes there are, and are held out from datagen's seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bodyschema.evaluation.core.seeds import EVAL_STREAM
from bodyschema.evaluation.core.sensing import sense

SELF = "self"
STREAM_WORD = 0x5E1F                       # second entropy word: self-recognition streams, apart from levels'
ROLE = {"body": 0, "other_arm": 1, "proprio_noise": 2, "visual_noise": 3}


@dataclass
class Episodes:
    kind: np.ndarray                   # (N,) str: "self" or a source
    q: np.ndarray                      # (N, T, Dq) rad, the robot's own trajectory
    proprio: np.ndarray                # (N, T, Dq) rad, q + noise
    visual: dict[str, np.ndarray]      # modality → (N, T, *out) float32: px, m, intensity in [0, 1]
    period: float                      # s between frames, as realised by the simulator


def episode_kinds(n: int, sources: Sequence[str]) -> np.ndarray:
    """n // 2 self episodes, the rest split as evenly as possible over the sources (first ones get the extra)."""
    others = n - n // 2
    counts = [others // len(sources) + (i < others % len(sources)) for i in range(len(sources))]
    return np.array([SELF] * (n // 2) + [k for k, c in zip(sources, counts) for _ in range(c)])


def _rng(seed: int, episode: int, role: str) -> np.random.Generator:
    """Episode i's generator per role: independent of how many episodes there are and of their kinds."""
    words = [EVAL_STREAM, STREAM_WORD, int(seed), int(episode), ROLE[role]]
    return np.random.default_rng(np.random.SeedSequence(words))


def make_episodes(config, robot, modalities: Sequence[str]) -> Episodes:
    """Babbling trajectories of every episode and what the robot feels and sees (noise included). config: a
    SelfRecognitionConfig (trials, sources, steps, period, delay, hold_s, noise σ, seed, progress)."""
    from tqdm import tqdm

    from bodyschema.datagen.samplers import Babbler
    kinds = episode_kinds(config.trials, config.sources)
    babbler = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, 1.0 / config.period, config.hold_s)
    period = 1.0 / babbler.rate_hz
    lag = max(1, round(config.delay / period))                      # frames of pre-roll, for q(t − delay)
    low, high = robot.sampling_ranges.T
    n, t, dq = config.trials, config.steps, robot.dq

    def babble(i, role):                                            # (T + lag, Dq) rad, clipped to the model box
        q = babbler.episode(_rng(config.seed, i, role), robot.sampling_ranges, t + lag)["q"]
        return np.clip(q.astype(np.float64), low, high)

    seen = np.empty((n, t, dq))                                     # (N, T, Dq) rad, the pose in view
    own = np.empty((n, t, dq))
    for i in tqdm(range(n), desc="babbling", disable=not config.progress):
        traj = babble(i, "body")
        own[i] = traj[lag:]
        if kinds[i] == "second_arm":
            seen[i] = babble(i, "other_arm")[lag:]                  # another arm, its own commands
        elif kinds[i] == "delayed":
            seen[i] = traj[:t]                                      # q(t − delay)
        else:
            seen[i] = own[i]                                        # self, and mirrored (flipped below)
    mirrored = kinds == "mirrored"
    noise = {**dict(config.visual_noise), "joints": config.proprio_noise}
    visual = {}
    for m in modalities:
        x = sense(robot, m, seen.reshape(n * t, dq), image_dtype=np.float32)      # (N·T, *out); float32 images
        x = x.reshape(n, t, *x.shape[1:])
        x[mirrored] = mirror(robot, m, x[mirrored].reshape(-1, *x.shape[2:])).reshape(x[mirrored].shape)
        visual[m] = _noisy(x, noise.get(m, 0.0), config.seed, "visual_noise", m == "image").astype(np.float32)
    proprio = _noisy(own, noise["joints"], config.seed, "proprio_noise", False)
    return Episodes(kinds, own, proprio, visual, period)


def mirror(robot, modality: str, x: np.ndarray) -> np.ndarray:
    """The mirrored view: a reflection through the camera's vertical plane (x_cam → −x_cam)."""
    if modality == "image":
        return np.ascontiguousarray(np.flip(x, axis=2))            # (M, H, W[, C]): columns reversed
    if modality == "ee_pixel":
        return np.stack([robot.image_size[1] - 1 - x[:, 0], x[:, 1]], axis=1)   # u about the centre column
    world_to_cam = robot.extrinsics()
    rot, trans = world_to_cam[:3, :3], world_to_cam[:3, 3]
    cam = x @ rot.T + trans                                         # (M, 3) m, camera frame
    cam[:, 0] *= -1.0
    return (cam - trans) @ rot                                      # back to the world frame


def _noisy(x: np.ndarray, sigma: float, seed: int, role: str, image: bool) -> np.ndarray:
    """x (N, T, *out) + σ·N(0, 1), drawn per episode from its own generator (images stay in [0, 1])."""
    if sigma == 0:
        return x
    out = np.empty(x.shape, np.float32 if image else np.float64)
    for i, xi in enumerate(x):
        out[i] = xi + sigma * _rng(seed, i, role).standard_normal(xi.shape)
    return np.clip(out, 0.0, 1.0, out=out) if image else out
