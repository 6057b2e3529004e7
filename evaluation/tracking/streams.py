"""The streams of the tracking benchmark: babbling arms filmed at a camera rate, and the calibration frames.

Every stream is one babbling episode (datagen's `Babbler`: position servos tracking random joint targets held
U(hold_s) s, under gravity, at datagen's pace by default) recorded at the frame rate (realised as whole physics
steps), its poses clipped to the box the models were trained on. What the robot reads per frame comes from the one
sensing function (core.sensing) plus Gaussian noise per modality; the joint velocity at each frame is kept for the
efference-copy command. Calibration frames: poses drawn uniformly from the same box, sensed the same way (the
lost-track threshold is set from F at their true poses). Every draw comes from the benchmark's own seed stream.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from bodyschema.base.modalities import is_image
from bodyschema.datagen.samplers import uniform
from bodyschema.evaluation.core.seeds import Stream, eval_rng
from bodyschema.evaluation.core.sensing import sense

TRACKING = Stream(0x7EAC_0000, {"streams": 0, "noise": 1, "calibration": 2})
CALIBRATION_KEY = 0xFFFF           # the noise key of the calibration frames (the streams' keys are rate indices)


@dataclass
class Streams:
    q: np.ndarray                          # (N, T, Dq) rad, the true poses
    qvel: np.ndarray                       # (N, T, Dq) rad/s, the joint velocities (the command's stand-in)
    observations: dict[str, np.ndarray]    # modality → (N, T, *out): m, px, rad; images float32 in [0, 1]
    period: float                          # s between frames, as realised by the simulator

    def frame(self, k: int, rows: Sequence[int] | slice = slice(None)) -> dict[str, np.ndarray]:
        """Frame k of the streams `rows`: modality → (n, *out) float64 (images float32)."""
        return {m: x[rows, k] for m, x in self.observations.items()}


def babble(robot, rate_hz: float, streams: int, frames: int, hold_s: tuple[float, float], seed: int,
           key: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(q (N, T, Dq) rad clipped to the model box, qvel (N, T, Dq) rad/s, realised period s) of `streams` babbling
    episodes at `rate_hz`; stream i draws from its own generator (key: the rate's index, so rates never share)."""
    from bodyschema.datagen.samplers import Babbler
    babbler = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, rate_hz, hold_s)
    low, high = robot.sampling_ranges.T
    q, qvel = np.empty((streams, frames, robot.dq)), np.empty((streams, frames, robot.dq))
    for i in range(streams):
        episode = babbler.episode(eval_rng(seed, None, "streams", key, i, stream=TRACKING), robot.sampling_ranges,
                                  frames)
        q[i] = np.clip(episode["q"].astype(np.float64), low, high)
        qvel[i] = episode["qvel"].astype(np.float64)
    return q, qvel, 1.0 / babbler.rate_hz


def observe(robot, modalities: Sequence[str], q: np.ndarray, noise: Mapping[str, float], seed: int,
            key: int) -> dict[str, np.ndarray]:
    """What each modality reads at poses q (N, T, Dq) (or (N, Dq)), plus Gaussian noise σ (its units); images stay
    in [0, 1] and float32 (long streams)."""
    lead, dq = q.shape[:-1], q.shape[-1]
    flat = q.reshape(-1, dq)
    out = {}
    for j, m in enumerate(modalities):
        x = sense(robot, m, flat, image_dtype=np.float32)                  # (N·T, *out)
        sigma = float(noise.get(m, 0.0))
        if sigma > 0:
            rng = eval_rng(seed, None, "noise", key, j, stream=TRACKING)
            x = x + sigma * rng.standard_normal(x.shape).astype(x.dtype)
            x = np.clip(x, 0.0, 1.0) if is_image(m) else x
        out[m] = x.reshape(*lead, *x.shape[1:])
    return out


def make_streams(robot, modalities: Sequence[str], rate_hz: float, streams: int, duration: float,
                 hold_s: tuple[float, float], noise: Mapping[str, float], seed: int, key: int) -> Streams:
    """`streams` babbling episodes of `duration` s at `rate_hz`, seen through every modality."""
    frames = max(2, int(round(duration * rate_hz)))
    q, qvel, period = babble(robot, rate_hz, streams, frames, hold_s, seed, key)
    return Streams(q, qvel, observe(robot, modalities, q, noise, seed, key), period)


def calibration_frames(robot, modalities: Sequence[str], n: int, noise: Mapping[str, float],
                       seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(q (n, Dq) rad, observations) at poses drawn uniformly from the model box: F at the truth, for thresholds."""
    q = uniform(eval_rng(seed, None, "calibration", stream=TRACKING), robot.sampling_ranges, n)
    return q, observe(robot, modalities, q, noise, seed, CALIBRATION_KEY)
