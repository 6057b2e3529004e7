"""The ways of following a stream compared side by side, each behind one interface (`Follower`), and the clock
that times the networks inside them.

  encoder          the image encoder's guess, frame by frame (no perception; needs an encoder and an image model)
  reading          the joint encoders' reading, frame by frame (no perception; the conditions fused with them): what
                   fusing the other senses must beat
  flow             a Pixel-AIF-style per-frame gradient flow: Euler steps on F from the last frame's belief, no motion
                   model, no proposal, no lost-track handling, with the tracker's budget of model evaluations. Its
                   Δt is the largest stable one for these models: 1/λ_max of F's Gauss–Newton curvature at the median
                   calibration frame (Pixel-AIF reaches stability instead by a small visual precision 1/Σ_v, which
                   at Δt 0.1 is a far smaller step: a handicap this baseline is spared)
  tracker          `aif.Tracker`: warm start moved by the belief's own velocity, the budget, lost-track restarts
  tracker+command  the same, moved by the motor command instead: the joint velocity at the previous frame (an
                   efference copy of the velocity the motors were producing as the interval began)
Every follower starts at the true first pose: the benchmark measures following, not the first acquisition.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from bodyschema.aif.free_energy import sensory_terms
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.aif.tracker import Tracker, reading_of
from bodyschema.aif.tracker_config import TrackerConfig
from bodyschema.base.modalities import is_image
from bodyschema.models.contract import FUSED_CALLS

METHODS = ("encoder", "reading", "flow", "tracker", "tracker+command")
CURVATURE_FRAMES = 32             # calibration frames whose curvature sets the flow's Δt (Jacobians of images cost)


class Clock:
    """Milliseconds spent inside timed models since the last `lap`."""

    def __init__(self):
        self.ms = 0.0

    def lap(self) -> float:
        spent, self.ms = self.ms, 0.0
        return spent


class Timed:
    """A model (or an encoder) whose calls add their wall time to a shared Clock; everything else is the model's."""

    def __init__(self, model, clock: Clock):
        self._model, self._clock = model, clock

    def __getattr__(self, name):
        attr = getattr(self._model, name)
        return self._timed_fused(attr) if name in FUSED_CALLS else attr

    def _timed_fused(self, call):
        """A fused call, timed with the derivative function it returns (predict_and_vjp's runs the backward)."""
        def timed(z):
            out, derivative = self._timed_call(call)(z)
            return out, (self._timed_call(derivative) if callable(derivative) else derivative)
        return timed

    def _timed_call(self, function):
        def timed(*args):
            start = time.perf_counter()
            try:
                return function(*args)
            finally:
                self._clock.ms += 1e3 * (time.perf_counter() - start)
        return timed

    def _call(self, name, *args):
        return self._timed_call(getattr(self._model, name))(*args)

    def predict(self, z):
        return self._call("predict", z)

    def jacobian(self, z):
        return self._call("jacobian", z)

    def vjp(self, z, v):
        return self._call("vjp", z, v)

    def precision(self, z):
        return self._call("precision", z)

    def precision_vjp(self, z, v):
        return self._call("precision_vjp", z, v)

    def encode(self, images):
        return self._call("encode", images)

    def save(self, path):
        self._model.save(path)


@dataclass
class Step:
    mu: np.ndarray                 # (B, Dz) rad
    restarted: np.ndarray          # (B,) bool: the follower detected lost track and restarted
    evaluations: float             # model evaluations per stream


class Follower:
    """Follows B streams: `start(q0)` then `frame(obs, command, dt)` per frame."""

    def start(self, q0: np.ndarray) -> None:
        raise NotImplementedError

    def frame(self, obs: dict[str, torch.Tensor], command: torch.Tensor | None, dt: float) -> Step:
        raise NotImplementedError


class GuessFollower(Follower):
    """A direct guess of the pose each frame, no perception: guess(observations) → (B, Dz) rad, kept in the box."""

    def __init__(self, guess: Callable[[dict], torch.Tensor], low: np.ndarray, high: np.ndarray):
        self.guess, self.low, self.high = guess, low, high

    def start(self, q0):
        pass

    def frame(self, obs, command, dt):
        mu = np.clip(self.guess(obs).double().numpy(), self.low, self.high)
        return Step(mu, np.zeros(len(mu), bool), 0.0)


class TrackerFollower(Follower):
    def __init__(self, tracker: Tracker, uses_command: bool):
        self.tracker, self.uses_command = tracker, uses_command

    def start(self, q0):
        self.tracker.reset(torch.from_numpy(q0))

    def frame(self, obs, command, dt):
        mu, _ = self.tracker.step(obs, command if self.uses_command else None, dt=dt)
        info = self.tracker.last
        return Step(mu.numpy(), info.restarted.numpy(), info.evaluations)


def euler_dt(perception: Perception, q: np.ndarray, observations: dict[str, np.ndarray]) -> float:
    """1/λ_max of F's Gauss–Newton curvature at the median of the first CURVATURE_FRAMES calibration frames, s: the
    largest Euler step that is stable along F's stiffest direction there."""
    n = min(len(q), CURVATURE_FRAMES)
    mu = torch.from_numpy(q[:n]).double()
    obs = {m: torch.from_numpy(np.asarray(x[:n], dtype=np.float64)) for m, x in observations.items()}
    pis = {m.modality: (torch.as_tensor(perception.precisions[m.modality], dtype=torch.float64)
                        .expand(n, *m.output_shape) if m.modality in perception.precisions else None)
           for m in perception.models}
    terms = sensory_terms(perception.models, obs, pis, mu, need_hessian=True, need_grad=True)
    stiffest = torch.linalg.eigvalsh(terms.hessian)[:, -1]                # (n,)
    return 1.0 / float(stiffest.median())


def flow_config(dt: float) -> PerceptionConfig:
    """Pixel-AIF's plain update (levels/plain.py): Euler steps, no step control, no trust region, at step dt."""
    return PerceptionConfig(method="flow", flow=FlowSettings(integrator="euler", dt=dt, step_control="none",
                                                             divergence_ratio=None), max_step=None, tol=0.0)


def make_followers(methods, models, tracker_config: TrackerConfig, encoder, precisions, calibration, seed: int
                   ) -> dict[str, Follower]:
    """The followers of `methods` over the (timed) models; calibration: (q, observations) of the calibration frames.
    The encoder row needs an encoder and an image model, the reading row a joints model; each is left out without."""
    q, observations = calibration
    out = {}
    has_image = any(is_image(m.modality) for m in models)
    low, high = np.asarray(models[0].body.q_low), np.asarray(models[0].body.q_high)
    reading = reading_of(models, len(low))
    for name in methods:
        if name == "encoder":
            if encoder is not None and has_image:
                out[name] = GuessFollower(lambda obs: encoder.encode(obs[encoder.modality]), low, high)
            continue
        if name == "reading":
            if reading is not None:
                out[name] = GuessFollower(lambda obs: obs[reading], low, high)
            continue
        if name == "flow":
            probe = Perception(models, precisions=precisions)
            config = TrackerConfig(perception=flow_config(euler_dt(probe, q, observations)),
                                   budget=tracker_config.budget, budget_ms=tracker_config.budget_ms, order=0,
                                   lost_threshold=None, restart="multistart", proposals=False)
            out[name] = TrackerFollower(Tracker(models, config, precisions=precisions, seed=seed), False)
            continue
        tracker = Tracker(models, tracker_config, encoder if has_image else None, precisions=precisions, seed=seed)
        if tracker.threshold is None:
            tracker.calibrate(observations, q)
        out[name] = TrackerFollower(tracker, name == "tracker+command")
    return out
