"""The seed streams of evaluation: `SeedSequence([EVAL_STREAM, ...])`, disjoint from datagen's
`SeedSequence([seed, shard])`, so evaluation poses are held out from any training set made with the same seed."""

from __future__ import annotations

import numpy as np

EVAL_STREAM = 0xB0D7_E7A1          # first entropy word of every evaluation seed sequence
PURPOSE = {"targets": 0, "beliefs": 1, "noise": 2, "starts": 3}


def eval_rng(seed: int, run: int, purpose: str, *keys: int) -> np.random.Generator:
    """The generator of one evaluation run for one purpose (targets, beliefs, noise, starts) and extra keys."""
    words = [EVAL_STREAM, int(seed), int(run), PURPOSE[purpose], *map(int, keys)]
    return np.random.default_rng(np.random.SeedSequence(words))
