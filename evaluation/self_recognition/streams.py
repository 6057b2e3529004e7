"""The streams of the self-recognition benchmark: what the babbling robot feels and what its camera sees.

Every episode the robot babbles (datagen's `Babbler`: position servos tracking random joint targets held for
random durations, under gravity), clipped to the sampling ranges (the box the models know). Proprioception is
q(t) + noise; the visual stream shows, per episode kind,
  self        its own body, q(t) (in the mirror: the robot knows the reflection, so this is its direct view);
  imitator    another agent copying its babbling: c + gain·(q(t − d) − c) + motor noise, c the centre of the
              box, one condition per delay d in `delays` (the babbling starts max(d) early);
  second_arm  another arm of the same kind babbling with its own commands, q'(t);
  mirrored    its own body in a mirror it does not know of: images flipped left-right, ee_pixel u → W − 1 − u,
              ee_xyz reflected through the camera's vertical plane (the principal point is centred).
Every condition (self, each imitator delay, each other source) has `trials` episodes. Every episode draws from its
own generators (`SeedSequence([EVAL_STREAM, STREAM_WORD, seed, episode, role])`), held out from datagen's seeds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bodyschema.base.modalities import is_image
from bodyschema.evaluation.core.seeds import EVAL_STREAM
from bodyschema.evaluation.core.sensing import sense

SELF = "self"
IMITATOR = "imitator"
STREAM_WORD = 0x5E1F                       # second entropy word: self-recognition streams, apart from levels'
ROLE = {"body": 0, "other_arm": 1, "proprio_noise": 2, "visual_noise": 3, "imitator_noise": 4}


@dataclass
class Episodes:
    kind: np.ndarray                   # (N,) str: "self" or a source
    condition: np.ndarray              # (N,) str: the kind, or "imitator_<d>s" for an imitator of delay d
    delay: np.ndarray                  # (N,) s, the imitator's realised delay (NaN for the other kinds)
    q: np.ndarray                      # (N, T, Dq) rad, the robot's own trajectory
    proprio: np.ndarray                # (N, T, Dq) rad, q + noise
    visual: dict[str, np.ndarray]      # modality → (N, T, *out) float32: px, m, intensity in [0, 1]
    period: float                      # s between frames, as realised by the simulator


def condition_name(kind: str, lag: int, period: float) -> str:
    return f"{IMITATOR}_{lag * period:.2f}s" if kind == IMITATOR else kind


def episode_conditions(trials: int, sources: Sequence[str], lags: Sequence[int],
                       period: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(kind, condition, lag in frames) of every episode: `trials` self episodes first, then `trials` per
    condition (the imitator once per lag, in order), so an episode's index does not depend on the later ones."""
    plan = [(SELF, 0)] + [(s, lag) for s in sources for lag in (lags if s == IMITATOR else [0])]
    kinds = np.repeat([k for k, _ in plan], trials)
    lag = np.repeat([g for _, g in plan], trials)
    names = np.repeat([condition_name(k, g, period) for k, g in plan], trials)
    return kinds, names, lag


def _rng(seed: int, episode: int, role: str) -> np.random.Generator:
    """Episode i's generator per role: independent of how many episodes there are and of their kinds."""
    words = [EVAL_STREAM, STREAM_WORD, int(seed), int(episode), ROLE[role]]
    return np.random.default_rng(np.random.SeedSequence(words))


def frames_of(delays: Sequence[float], period: float) -> list[int]:
    """Delays (s) as whole frames of `period`."""
    return [int(round(d / period)) for d in delays]


def make_episodes(config, robot, modalities: Sequence[str]) -> Episodes:
    """Babbling trajectories of every episode and what the robot feels and sees (noise included). config: a
    SelfRecognitionConfig (trials, sources, delays, imitation gain and noise, steps, period, hold_s, noise σ,
    seed, progress)."""
    from tqdm import tqdm

    from bodyschema.datagen.samplers import Babbler
    babbler = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, 1.0 / config.period, config.hold_s)
    period = 1.0 / babbler.rate_hz
    kinds, names, lags = episode_conditions(config.trials, config.sources, frames_of(config.delays, period), period)
    pre = int(lags.max())                                           # frames of pre-roll, for q(t − d)
    low, high = robot.sampling_ranges.T
    n, t, dq = len(kinds), config.steps, robot.dq

    def babble(i, role):                                            # (T + pre, Dq) rad, clipped to the model box
        q = babbler.episode(_rng(config.seed, i, role), robot.sampling_ranges, t + pre)["q"]
        return np.clip(q.astype(np.float64), low, high)

    seen = np.empty((n, t, dq))                                     # (N, T, Dq) rad, the pose in view
    own = np.empty((n, t, dq))
    for i in tqdm(range(n), desc="babbling", disable=not config.progress):
        traj = babble(i, "body")
        own[i] = traj[pre:]
        if kinds[i] == "second_arm":
            seen[i] = babble(i, "other_arm")[pre:]                  # another arm, its own commands
        elif kinds[i] == IMITATOR:
            seen[i] = imitate(traj[pre - lags[i]:pre - lags[i] + t], config, robot, _rng(config.seed, i,
                                                                                         "imitator_noise"))
        else:
            seen[i] = own[i]                                        # self, and mirrored (flipped below)
    mirrored = kinds == "mirrored"
    noise = {**dict(config.visual_noise), "joints": config.proprio_noise}
    visual = {}
    for m in modalities:
        x = sense(robot, m, seen.reshape(n * t, dq), image_dtype=np.float32)      # (N·T, *out); float32 images
        x = x.reshape(n, t, *x.shape[1:])
        x[mirrored] = mirror(robot, m, x[mirrored].reshape(-1, *x.shape[2:])).reshape(x[mirrored].shape)
        visual[m] = _noisy(x, noise.get(m, 0.0), config.seed, "visual_noise", is_image(m)).astype(np.float32)
    proprio = _noisy(own, noise["joints"], config.seed, "proprio_noise", False)
    delay = np.where(kinds == IMITATOR, lags * period, np.nan)
    return Episodes(kinds, names, delay, own, proprio, visual, period)


def imitate(late: np.ndarray, config, robot, rng: np.random.Generator) -> np.ndarray:
    """The imitator's pose (T, Dq) rad from the robot's late pose q(t − d) (T, Dq): about the centre c of the box,
    scaled by the gain, plus white motor noise σ (rad), kept inside the box the models know."""
    low, high = robot.sampling_ranges.T
    centre = (low + high) / 2.0
    pose = centre + config.imitation_gain * (late - centre) + config.imitation_noise * rng.standard_normal(late.shape)
    return np.clip(pose, low, high)


def mirror(robot, modality: str, x: np.ndarray) -> np.ndarray:
    """The mirrored view: a reflection through the camera's vertical plane (x_cam → −x_cam)."""
    if is_image(modality):
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
