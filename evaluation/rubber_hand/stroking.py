"""Visuo-tactile stroking and the belief that the seen hand is mine: the touch stream of the rubber-hand benchmark.

A brush strokes the hidden real hand (felt: the touch modality, stroke times t_k) and the seen hand (seen strokes at
t_k in the synchronous condition, t_k + lag in the asynchronous one). Whether the seen hand is the robot's own is a
binary hidden cause c; its posterior is the exact minimiser of the free energy over c (Bayesian causal inference of
body ownership, Samad, Chung & Shams 2015):

    log-odds(own | t) = logit(prior) + Σ_{felt t_k ≤ t} log N(Δ_k; 0, σ_t²) / U(Δ_k; stroke interval)
                                     + log N(d; 0, σ_s²) / U(d; spatial range)
Δ_k: seen − felt time of the nearest seen stroke (s); d: distance (m) between the seen hand and the felt one. Under
"mine" a stroke is seen when it is felt (within the temporal binding window σ_t) and the seen hand lies near the
felt one (σ_s); under "not mine" both are uniform. The visual stream then enters perception with its precision
weighted by q(own) (mean-field expectation of the precision under q(c)).
"""

from __future__ import annotations

import numpy as np

MODES = ("synchronous", "asynchronous", "vision_only")   # vision_only: no brush at all (Rohde et al. 2011's control)


def felt_strokes(rng: np.random.Generator, duration: float, rate_hz: float, jitter_s: float) -> np.ndarray:
    """Stroke times (K,) s in [0, duration): one per 1/rate_hz, each interval jittered by ±jitter_s (uniform)."""
    interval = 1.0 / rate_hz
    n = int(np.ceil(duration * rate_hz)) + 1
    steps = interval + rng.uniform(-jitter_s, jitter_s, n)                  # (K,) s between strokes
    times = 0.5 * interval + np.cumsum(steps) - steps[0]
    return times[times < duration]


def strokes(felt: np.ndarray, mode: str, lag_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(felt, seen) stroke times (K,) s of a mode: seen = felt, later by lag_s when asynchronous; none at all
    when vision_only."""
    if mode == "vision_only":
        return np.empty(0), np.empty(0)
    return felt, (felt if mode == "synchronous" else felt + lag_s)


def nearest_seen(felt: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """(K,) s: for every felt stroke the seen stroke closest in time (+inf when none was seen)."""
    if seen.size == 0:
        return np.full(felt.shape, np.inf)
    return seen[np.abs(seen[None, :] - felt[:, None]).argmin(axis=1)]


def temporal_log_lr(felt: np.ndarray, seen: np.ndarray, sigma_s: float, interval_s: float) -> np.ndarray:
    """Per felt stroke (K,): log N(Δ; 0, σ²) − log U(interval) with Δ = the nearest seen stroke − the felt one.
    Under "not mine" Δ is uniform over one stroke interval (the nearest of a periodic train lies within ±½)."""
    delta = nearest_seen(felt, seen) - felt                                       # (K,) s
    return -0.5 * (delta / sigma_s) ** 2 - np.log(sigma_s * np.sqrt(2 * np.pi)) + np.log(interval_s)


def spatial_log_lr(distance_m: np.ndarray, sigma_m: float, range_m: float) -> np.ndarray:
    """log N(d; 0, σ²) − log U(range), for the distance d (m) between the seen and the felt hand."""
    return -0.5 * (distance_m / sigma_m) ** 2 - np.log(sigma_m * np.sqrt(2 * np.pi)) + np.log(range_m)


def ownership(felt: list[np.ndarray], seen: list[np.ndarray], distance_m: np.ndarray, frame_times: np.ndarray,
              config) -> np.ndarray:
    """q(own) per episode and frame (N, T): the posterior after the strokes felt up to each frame time. config: a
    RubberHandConfig (prior_own, binding_sigma_s, stroke_rate_hz, spatial_sigma, spatial_range)."""
    base = np.log(config.prior_own / (1 - config.prior_own)) + spatial_log_lr(
        np.asarray(distance_m), config.spatial_sigma, config.spatial_range)          # (N,)
    out = np.empty((len(felt), len(frame_times)))
    for i, (f, s) in enumerate(zip(felt, seen)):
        # a felt stroke counts once its seen partner has come too, or once the binding window (3σ) has passed
        known = np.clip(nearest_seen(f, s), f, f + 3 * config.binding_sigma_s)       # (K,) s
        evidence = temporal_log_lr(f, s, config.binding_sigma_s, 1.0 / config.stroke_rate_hz)   # (K,)
        counted = known[None, :] <= frame_times[:, None]                        # (T, K)
        out[i] = base[i] + (counted * evidence[None, :]).sum(axis=1)
    return 1.0 / (1.0 + np.exp(-np.clip(out, -700, 700)))
