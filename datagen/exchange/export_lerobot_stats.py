"""meta/stats.json of a LeRobot export: per feature the keys LeRobot ≥ 0.4's writer produces (compute_stats.py:
`get_feature_stats`): min, max, mean, std, count and the quantiles q01, q10, q50, q90, q99 (`DEFAULT_QUANTILES`, named
f"q{int(q * 100):02d}"), which a policy normalised by QUANTILES (pi0.5) needs.

Shapes as LeRobot's: a vector feature of width k gives (k,) per key, an image (C, 1, 1) per channel in [0, 1] (pixel
/ 255), count (1,) the number of frames. The values are exact over the whole dataset: numpy's quantiles (method
"linear") of every frame's value, where LeRobot estimates them from a 5000-bin histogram per episode and averages
episodes weighted by length; images use every pixel (LeRobot samples frames). uint8 images are counted in a 256-bin
histogram per channel, from which the exact min, max, mean, std and linear quantiles follow without keeping pixels.
"""

from __future__ import annotations

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)                 # LeRobot's DEFAULT_QUANTILES
QUANTILE_KEYS = tuple(f"q{int(q * 100):02d}" for q in QUANTILES)
KEYS = ("min", "max", "mean", "std", "count", *QUANTILE_KEYS)


class LeRobotStats:
    """Collects each feature's values block by block (vectors kept, images as per-channel histograms)."""

    def __init__(self):
        self.vectors: dict[str, list[np.ndarray]] = {}
        self.images: dict[str, tuple[np.ndarray, int]] = {}   # key → ((C, 256) pixel counts, frames)

    def add(self, key: str, values: np.ndarray) -> None:
        """(b, k) values of a vector feature (their own dtype: float32 and int64 kept exactly)."""
        self.vectors.setdefault(key, []).append(np.asarray(values).reshape(len(values), -1))

    def add_images(self, key: str, images: np.ndarray) -> None:
        """(b, H, W[, C]) uint8 frames."""
        b = len(images)
        pixels = images.reshape(b, -1, images.shape[3] if images.ndim == 4 else 1)       # (b, H·W, C)
        counts = np.stack([np.bincount(pixels[:, :, c].ravel(), minlength=256) for c in range(pixels.shape[2])])
        old, frames = self.images.get(key, (0, 0))
        self.images[key] = (old + counts, frames + b)

    def as_json(self) -> dict[str, dict[str, list]]:
        out = {}
        for key, blocks in self.vectors.items():
            v = np.concatenate(blocks).astype(np.float64)                                 # (N, k)
            stats = {"min": v.min(0), "max": v.max(0), "mean": v.mean(0), "std": v.std(0),
                     **dict(zip(QUANTILE_KEYS, np.quantile(v, QUANTILES, axis=0)))}
            out[key] = {k: s.tolist() for k, s in stats.items()} | {"count": [len(v)]}
        for key, (counts, frames) in self.images.items():
            stats = {k: np.array([s / 255.0 for s in column]).reshape(-1, 1, 1).tolist()    # (C, 1, 1) in [0, 1]
                     for k, column in zip(KEYS[:4] + QUANTILE_KEYS, zip(*map(_histogram_stats, counts)))}
            out[key] = stats | {"count": [frames]}
        return {key: {k: out[key][k] for k in KEYS} for key in out}


def _histogram_stats(counts: np.ndarray) -> tuple[float, ...]:
    """(min, max, mean, std, *quantiles) of the values 0…255 counted `counts` times, as numpy gives them of the
    values themselves (quantile method "linear": order statistic floor(h) plus its fraction toward the next, with
    h = (n - 1)·q)."""
    values = np.arange(len(counts), dtype=np.float64)
    n = counts.sum()
    mean = (values * counts).sum() / n
    std = np.sqrt((((values - mean) ** 2) * counts).sum() / n)
    present = np.flatnonzero(counts)
    ends = np.cumsum(counts)                                             # order statistic i is the first v: ends[v] > i

    def order(i: np.ndarray) -> np.ndarray:
        return np.searchsorted(ends, i, side="right").astype(np.float64)

    h = (n - 1) * np.asarray(QUANTILES)
    low = np.floor(h)
    quantiles = order(low) + (h - low) * (order(np.minimum(low + 1, n - 1)) - order(low))
    return (float(present[0]), float(present[-1]), float(mean), float(std), *map(float, quantiles))
