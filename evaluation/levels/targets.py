"""Held-out evaluation targets and the initial beliefs of levels 1–3 ("where is my body?").

Targets are true poses drawn uniformly from the robot's sampling ranges (the distribution babbling sampled)
with their observations from the simulator, drawn from `core.seeds.eval_rng` (held out from datagen's seeds).
Initial beliefs, as in Pixel-AIF (Sancaktar et al. 2020, §4.1):
  level 1  one random joint off by ±5–10° (the sign flipped where the belief would leave the range);
  level 2  every joint off by ±5–10° (same rule per joint);
  level 3  the belief starts at another random target's pose.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import torch

from bodyschema.base.modalities import KINEMATIC, images_in, is_image, is_projection
from bodyschema.datagen.samplers import uniform
from bodyschema.errors import must_be
from bodyschema.models.scaling import IMAGE_SCALE

OFFSET_DEG = (5.0, 10.0)           # level 1–2 belief offsets, uniform in magnitude


@dataclass
class Targets:
    q: np.ndarray                          # (N, Dq) rad, true poses
    observations: dict[str, np.ndarray]    # modality → (N, *out): ee_xyz m, ee_pixel[_<camera>] px, joints rad,
                                           # image[_<camera>] [0, 1]

    def tensors(self, modalities) -> dict[str, torch.Tensor]:
        """Observations of the given modalities as float64 tensors."""
        missing = sorted(set(modalities) - set(self.observations))
        if missing:
            raise ValueError(must_be("modalities", f"among the simulated observations {sorted(self.observations)}",
                                     missing, "Models of other modalities cannot be evaluated on this robot."))
        return {m: torch.from_numpy(np.asarray(self.observations[m], dtype=np.float64)) for m in modalities}


def make_targets(robot, n: int, rng: np.random.Generator, image: bool = False,
                 noise: Mapping[str, float] | None = None, noise_rng: np.random.Generator | None = None) -> Targets:
    """n poses from `robot.sampling_ranges` and what the simulator senses there, with optional Gaussian noise
    (standard deviation per modality, in its units: m, px, rad, intensity) added to the observations."""
    q = uniform(rng, robot.sampling_ranges, n)                            # (N, Dq) rad
    sensed = robot.observe(q, image=image)
    obs = {m: sensed[m].astype(np.float64) for m in sensed if m in KINEMATIC or is_projection(m)}
    obs["joints"] = q.copy()                                              # ee_xyz, ee_rot, ee_pixel[_<camera>], joints
    for camera in images_in(sensed):                                      # uint8 → [0, 1]
        obs[camera] = sensed[camera].astype(np.float64) / IMAGE_SCALE
    return Targets(q, add_noise(obs, noise, noise_rng if noise_rng is not None else rng))


def add_noise(obs: dict[str, np.ndarray], noise: Mapping[str, float] | None,
              rng: np.random.Generator) -> dict[str, np.ndarray]:
    """`obs` with Gaussian noise of standard deviation `noise[modality]` (in its units) added; images stay in [0, 1]."""
    for modality, sigma in (noise or {}).items():
        if modality not in obs:
            raise ValueError(must_be("noise modality", f"one of {sorted(obs)}", modality))
        if not sigma >= 0:
            raise ValueError(must_be(f"noise[{modality!r}]", "a standard deviation ≥ 0", sigma))
        if sigma > 0:
            obs[modality] = obs[modality] + sigma * rng.standard_normal(obs[modality].shape)
            if is_image(modality):
                obs[modality] = np.clip(obs[modality], 0.0, 1.0)
    return obs


def initial_beliefs(level: int, q: np.ndarray, ranges: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The initial belief μ0 (N, Dq) rad of every trial at `level` for true poses q (N, Dq)."""
    n, dq = q.shape
    low, high = np.asarray(ranges, dtype=np.float64).T
    if level == 3:
        if n == 1:
            return uniform(rng, np.asarray(ranges, dtype=np.float64), 1)
        order = rng.permutation(n)                                         # a derangement: each trial gets
        mu0 = np.empty_like(q)                                             # the pose of another target
        mu0[order] = q[np.roll(order, -1)]
        return mu0
    if level not in (1, 2):
        raise ValueError(must_be("level", "1, 2 or 3", level))
    magnitude = np.deg2rad(rng.uniform(*OFFSET_DEG, size=(n, dq)))        # (N, Dq) rad
    sign = rng.choice([-1.0, 1.0], size=(n, dq))
    if level == 1:
        mask = np.zeros((n, dq))
        mask[np.arange(n), rng.integers(0, dq, size=n)] = 1.0
        magnitude = magnitude * mask
    mu0 = q + sign * magnitude
    outside = (mu0 < low) | (mu0 > high)
    mu0 = np.where(outside, q - sign * magnitude, mu0)                     # flip the sign where it would leave
    return np.clip(mu0, low, high)                                         # a range narrower than 2·offset
