"""Tracker: perception of B streams frame by frame, each frame's belief warm-started from the last one.

Per frame (`Tracker.step`):
  1. predict   the belief moves by the motor command (joint velocities, rad/s; an efference copy) or, without one, by
               its own velocity: μ ← μ + Δt μ' (+ ½ Δt² μ'' at order 2), the generalized coordinates of the belief;
               a direct guess of the pose competes (`proposals`): a joints sensor's reading, else the image
               encoder's (`guess`); the one of lower F is the frame's start;
  2. perceive  a `Perception` runs from there within a budget of model evaluations per stream (and, on top, of
               milliseconds: fewer updates when the last frames' cost per evaluation says the budget would overrun);
  3. lost?     a stream whose F exceeds the lost-track threshold (calibrated from F at the true poses of training
               frames, `calibrate`, or given), or whose belief a low-dimensional sensor contradicts beyond its own
               calibrated noise (`consistency`), restarts from the frame's guess or from several starts
               (aif/multistart.py); of the restart and the tracked belief, the one the sensors accept, then the
               lower F, wins;
  4. motion    the belief's velocity (and acceleration) follow the frame-to-frame change of μ through a fixed-gain
               α-β filter (Benedict & Bordner 1962). Perception itself runs at order 0: a frame is seen at one
               instant, so F of one frame holds no information on μ' (a generalized-coordinate perception would
               leave μ' where it started); the motion is read across frames instead.
A rejected frame (bad shape, dtype, non-finite reading, dt ≤ 0, a command of the wrong size) raises the house
error naming the frame index and leaves the tracker's state as it was.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import torch

from bodyschema.aif.consistency import SensorChecks, above_spread
from bodyschema.aif.frame_check import checked_frame
from bodyschema.aif.multistart import infer_multistart
from bodyschema.aif.perception import Perception, as_inputs
from bodyschema.aif.tracker_config import DEFAULTS, TrackerConfig, least_steps, steps_within
from bodyschema.errors import must_be
from bodyschema.models.contract import as_input

MS_SMOOTHING = 0.8          # weight of the past in the running cost per evaluation (the millisecond budget)
PROPOSAL_EVALUATIONS = 2    # F at the predicted belief and at the frame's guess


def reading_of(models, latent_dim: int) -> str | None:
    """The modality of a joints sensor among `models`, whose observation is the belief itself (rad), else None."""
    return next((m.modality for m in models if m.modality == "joints" and tuple(m.output_shape) == (latent_dim,)),
                None)


@dataclass
class FrameInfo:
    """What the last accepted frame cost and found, per stream where shaped (B,)."""

    lost: torch.Tensor              # (B,) bool: F still above the threshold after any restart
    restarted: torch.Tensor         # (B,) bool: a restart ran on this frame
    steps: int                      # updates of the per-frame perception
    evaluations: float              # model evaluations per stream, restarts included
    ms: float                       # wall time of the whole step
    timings: dict[str, float] = field(default_factory=dict)   # ms: "perceive", "restart"


class Tracker:
    """Tracks B streams of observations of one body (any set of SensoryModels, as `Perception` takes them).

    encoder: an image encoder (`encode(images) → (N, Dz) rad`, images of its `modality`), the frame's guess where no
    joints sensor reads the pose (config.guess); precisions, limits: as `Perception`'s; seed: the multi-start draws
    (`reset` draws them anew from it)."""

    def __init__(self, models: Sequence, config: TrackerConfig = DEFAULTS, encoder=None,
                 precisions: Mapping[str, float | torch.Tensor] | None = None,
                 limits: tuple[Sequence[float], Sequence[float]] | None = None, seed: int = 0):
        self.config, self.encoder, self.seed = config, encoder, seed
        self.perception = Perception(models, config.perception, precisions, limits)
        resolved = self.perception.config
        self.reading = reading_of(self.perception.models, self.latent_dim)
        self.guesses = self._guess_source(config.guess, encoder)
        self.proposes = config.proposals and self.guesses is not None
        spent = PROPOSAL_EVALUATIONS if self.proposes else 0
        self.steps = steps_within(resolved, config.budget - spent)
        if self.steps < least_steps(resolved):
            need = spent + next(n for n in range(1, 100) if steps_within(resolved, n) >= least_steps(resolved))
            raise ValueError(must_be("budget", f"at least {need} model evaluations for one update of "
                                     f"{resolved.method}{' after the proposal' if spent else ''}",
                                     config.budget))
        self.restart = config.restart if config.restart != "auto" else ("guess" if self.guesses else "multistart")
        if self.restart == "guess" and self.guesses is None:
            raise ValueError(must_be("restart", "'multistart' without a joints sensor or an image encoder", "guess"))
        self.threshold = config.lost_threshold
        self.settled: float | None = None       # F of a start good enough to skip a frame's updates (`calibrate`)
        self.sensors = SensorChecks.of(self.perception, precisions, limits) if config.consistency else None
        self._runs: dict[int, Perception] = {}
        self._restarts = self.perception.with_config(replace(config.restart_perception, record=False))
        self.reset()

    def _guess_source(self, choice: str, encoder) -> str | None:
        """The source of the frame's guess, "reading", "encoder" or None (none): config.guess, checked against the
        models this tracker perceives."""
        has_encoder = encoder is not None and encoder.modality in self._modalities
        if choice == "reading" and self.reading is None:
            raise ValueError(must_be("guess", "'encoder' or 'auto' without a joints model", "reading"))
        if choice == "encoder" and not has_encoder:
            raise ValueError(must_be("guess", "'reading' or 'auto' without an encoder of a perceived image", "encoder"))
        if choice == "auto":
            return "reading" if self.reading else ("encoder" if has_encoder else None)
        return choice

    @property
    def _modalities(self) -> set[str]:
        return {m.modality for m in self.perception.models}

    @property
    def latent_dim(self) -> int:
        return self.perception.latent_dim

    # ---- public -----------------------------------------------------------------------------------------
    def reset(self, mu0=None) -> None:
        """Forget every stream. mu0 (B, Dz) rad: where the next frame's perception starts (velocity 0); None: the
        next frame is acquired by a restart (encoder guess or multi-start)."""
        k = self.config.order + 1
        self.mu_tilde: torch.Tensor | None = None                            # (B, K, Dz) rad, rad/s, rad/s²
        if mu0 is not None:
            mu0 = as_input(mu0)
            if not isinstance(mu0, torch.Tensor) or mu0.ndim != 2 or mu0.shape[1] != self.latent_dim \
                    or not torch.isfinite(mu0).all():
                raise ValueError(must_be("mu0", f"a finite (B, {self.latent_dim}) belief in rad or None",
                                         tuple(getattr(mu0, "shape", ())) or type(mu0).__name__))
            self.mu_tilde = torch.zeros(len(mu0), k, self.latent_dim, dtype=torch.float64)
            self.mu_tilde[:, 0] = self._clamp(mu0.to(torch.float64))
        self.free: torch.Tensor | None = None
        self.frames = 0                                                      # frames accepted since the reset
        self.last: FrameInfo | None = None
        self._ms_per_evaluation: float | None = None
        self._generator = torch.Generator().manual_seed(self.seed)

    def calibrate(self, observations, q_true) -> float:
        """Set the lost-track threshold from F at the true poses q_true (N, Dz) rad of frames `observations`
        (modality → (N, *out)): its `lost_quantile` plus `lost_slack` times that quantile's distance to the median.
        → the threshold."""
        free = self.perception.free_energy(observations, q_true).numpy()
        if not np.isfinite(free).all():
            raise ValueError(must_be("F at the calibration poses", "finite", "non-finite values",
                                     "Calibrate on frames the models explain (training frames)."))
        self.threshold = above_spread(free, self.config.lost_quantile, self.config.lost_slack)
        if self.config.settle_quantile is not None:
            self.settled = float(np.quantile(free, self.config.settle_quantile))
        if self.sensors is not None:
            self.sensors.calibrate(observations, q_true, self.config.lost_quantile, self.config.consistency_slack)
        return self.threshold

    def step(self, observations, command=None, dt: float | None = None):
        """One frame of every stream: observations modality → (B, *out); command (B, Dz) rad/s or None; dt s since
        the last frame. → (belief μ (B, Dz) rad, F (B,)); `self.last` holds the frame's costs and lost streams."""
        start = time.perf_counter()
        streams = self.mu_tilde.shape[0] if self.mu_tilde is not None else None
        obs, command, dt = checked_frame(self.perception, as_inputs(observations), as_input(command), dt,
                                         self.frames, streams)
        b = next(iter(obs.values())).shape[0]
        predicted = self._predicted(command, dt)                             # (B, Dz) or None: acquire
        timings, steps, evaluations, guess = {}, self._budgeted_steps(), 0, None
        if predicted is None:
            mu, free = predicted, torch.full((b,), torch.inf, dtype=torch.float64)
        else:
            tick = time.perf_counter()
            mu, free = predicted, torch.full((b,), torch.inf, dtype=torch.float64)
            if self.proposes:
                mu, guess, free = self._proposed(obs, predicted)
                evaluations += PROPOSAL_EVALUATIONS * b
            mu, free, spent = self._perceived(obs, mu, free, steps)
            timings["perceive"] = 1e3 * (time.perf_counter() - tick)
            evaluations += spent
            self._learn_cost(timings["perceive"], evaluations / b)
        contradicted = self._contradicted(obs, mu)
        restart = self._lost(free, contradicted)
        if restart.any():
            tick = time.perf_counter()
            mu, free, contradicted, extra = self._restarted(obs, mu, free, contradicted, predicted, restart, guess)
            timings["restart"] = 1e3 * (time.perf_counter() - tick)
            evaluations += extra
        lost = self._lost(free, contradicted)
        self._commit(mu, free, restart, command, dt)
        self.last = FrameInfo(lost, restart, steps, evaluations / b, 1e3 * (time.perf_counter() - start), timings)
        return mu.clone(), free.clone()

    # ---- a frame's parts --------------------------------------------------------------------------------
    def _predicted(self, command, dt) -> torch.Tensor | None:
        """Where each stream's belief should be now (B, Dz) rad; None before the first belief."""
        if self.mu_tilde is None:
            return None
        u = self.mu_tilde
        if command is not None:
            return self._clamp(u[:, 0] + dt * command)
        mu = u[:, 0].clone()
        if self.config.order >= 1:
            mu = mu + dt * u[:, 1]
        if self.config.order == 2:
            mu = mu + 0.5 * dt ** 2 * u[:, 2]
        return self._clamp(mu)

    def _guess(self, obs) -> torch.Tensor:
        """The frame's direct guess of every stream's pose (B, Dz) rad: the joints reading or the encoder's."""
        if self.guesses == "reading":
            return self._clamp(obs[self.reading].to(torch.float64))
        return self._clamp(self.encoder.encode(obs[self.encoder.modality]).to(torch.float64))

    def _proposed(self, obs, predicted) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Per stream the lower-F start of the predicted belief and the frame's guess, the guess (a restart of this
        frame reuses it) and F at the start. → (B, Dz), (B, Dz) rad, (B,)"""
        b = len(predicted)
        guess = self._guess(obs)                                                          # (B, Dz) rad
        twice = {m: torch.cat([x, x]) for m, x in obs.items()}
        both = self.perception.free_energy(twice, torch.cat([predicted, guess]))          # (2B,)
        worse = ~(both[b:] < both[:b])                                                    # NaN-safe: predicted wins
        return torch.where(worse[:, None], predicted, guess), guess, torch.where(worse, both[:b], both[b:])

    def _perceived(self, obs, start, start_free, steps: int) -> tuple[torch.Tensor, torch.Tensor, int]:
        """The frame's updates from start (B, Dz) rad, for the streams whose F there (B,) is not settled already.
        → (μ (B, Dz), F (B,), evaluations)"""
        moving = torch.ones(len(start), dtype=torch.bool) if self.settled is None else ~(start_free <= self.settled)
        if not moving.any():
            return start, start_free, 0
        rows = torch.nonzero(moving).squeeze(-1)
        sub = obs if moving.all() else {m: x[rows] for m, x in obs.items()}
        result = self._run(steps).infer(sub, start[rows])
        mu, free = start.clone(), start_free.clone()
        mu[rows], free[rows] = result.mu, torch.where(result.diverged, torch.inf, result.F)
        return mu, free, result.evaluations

    def _budgeted_steps(self) -> int:
        """The updates of this frame: the evaluation budget, cut to the millisecond budget once a cost is known."""
        if self.config.budget_ms is None or self._ms_per_evaluation is None:
            return self.steps
        affordable = int(self.config.budget_ms / max(self._ms_per_evaluation, 1e-6))
        resolved = self.perception.config
        return max(least_steps(resolved), min(self.steps, steps_within(resolved, affordable)))

    def _learn_cost(self, ms: float, evaluations: float) -> None:
        cost = ms / max(evaluations, 1.0)
        past = self._ms_per_evaluation
        self._ms_per_evaluation = cost if past is None else MS_SMOOTHING * past + (1 - MS_SMOOTHING) * cost

    def _run(self, steps: int) -> Perception:
        if steps not in self._runs:
            self._runs[steps] = self.perception.with_config(replace(self.perception.config, max_steps=steps,
                                                                    record=False))
        return self._runs[steps]

    def _restarted(self, obs, mu, free, contradicted, predicted, rows_mask, guess=None):
        """Restart the streams in rows_mask from the frame's guess or several starts; per stream, of the restart and
        its tracked belief, the one no sensor contradicts, then the lower F. guess: this frame's guess (B, Dz) rad,
        else None (asked here). From the guess, not from the lower F of it and the frame's belief: from the
        belief, the lower in most restarts, the restart stays in its local basin (measured, nao_arm 30 Hz: 1.96°
        against 1.84° mean error). → (μ, F, contradicted (B,) bool, evaluations)."""
        rows = torch.nonzero(rows_mask).squeeze(-1)
        sub = {name: x[rows] for name, x in obs.items()}
        run = self._restarts
        if self.restart == "guess":
            start = guess[rows] if guess is not None else self._guess(sub)                 # (b, Dz) rad
            result = run.infer(sub, start)
            new_mu, new_free, evaluations = result.mu, torch.where(result.diverged, torch.inf, result.F), \
                result.evaluations
        else:
            starts = self._starts(rows, mu, predicted)                                     # (b, S, Dz)
            screen = max(1, run.config.max_steps // 10)
            ms = infer_multistart(run, sub, starts, screen_steps=screen, keep=2)
            new_mu, evaluations = ms.result.mu, ms.evaluations
            new_free = torch.where(ms.result.diverged, torch.inf, ms.result.F)
        mu = torch.zeros(len(free), self.latent_dim, dtype=torch.float64) if mu is None else mu.clone()
        free, contradicted = free.clone(), contradicted.clone()
        new_contradicted, old_contradicted = self._contradicted(sub, new_mu), contradicted[rows]
        lower = ~(new_free >= free[rows])                                                  # NaN-safe: a finite wins
        better = (old_contradicted & ~new_contradicted) | ((old_contradicted == new_contradicted) & lower)
        mu[rows[better]], free[rows[better]] = new_mu[better], new_free[better]
        contradicted[rows[better]] = new_contradicted[better]
        return mu, free, contradicted, evaluations

    def _starts(self, rows, mu, predicted) -> torch.Tensor:
        """Multi-start seeds per lost stream: its tracked and predicted beliefs, then uniform draws in the limits."""
        s = self.config.restart_starts
        draws = self.perception.low + (self.perception.high - self.perception.low) * \
            torch.rand(len(rows), s, self.latent_dim, generator=self._generator, dtype=torch.float64)
        if mu is not None:
            draws[:, 0], draws[:, 1] = mu[rows], predicted[rows]
        return draws

    def _lost(self, free, contradicted) -> torch.Tensor:
        """(B,) bool: F above the lost-track threshold (not finite, without one), or a sensor contradicts."""
        return contradicted | (~torch.isfinite(free) if self.threshold is None else ~(free <= self.threshold))

    def _contradicted(self, obs, mu) -> torch.Tensor:
        """(B,) bool: a checked sensor contradicts the belief mu (aif/consistency.py); all False without checks."""
        if self.sensors is None:
            return torch.zeros(next(iter(obs.values())).shape[0], dtype=torch.bool)
        return self.sensors.contradicted(obs, mu)

    def _commit(self, mu, free, restarted, command, dt) -> None:
        """The new state: μ, and its motion from the frame-to-frame change (a restarted stream's motion unknown: 0,
        or the command)."""
        k = self.config.order + 1
        new = torch.zeros(len(mu), k, self.latent_dim, dtype=torch.float64)
        new[:, 0] = mu
        if k > 1 and self.mu_tilde is not None:
            old, gain = self.mu_tilde, self.config.motion_gain
            seen = (mu - old[:, 0]) / dt                                      # (B, Dz) rad/s, finite difference
            prior = command if command is not None else old[:, 1] + (dt * old[:, 2] if k > 2 else 0.0)
            new[:, 1] = prior + gain * (seen - prior)
            if k > 2:
                new[:, 2] = old[:, 2] + gain * ((new[:, 1] - old[:, 1]) / dt - old[:, 2])
            new[restarted, 1:] = 0.0
            if command is not None:
                new[restarted, 1] = command[restarted]
        self.mu_tilde, self.free = new, free
        self.frames += 1

    def _clamp(self, mu: torch.Tensor) -> torch.Tensor:
        return torch.minimum(torch.maximum(mu, self.perception.low), self.perception.high)
