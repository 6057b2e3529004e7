"""The seed streams of evaluation: `SeedSequence([EVAL_STREAM, ...])`, disjoint from datagen's
`SeedSequence([seed, shard])`, so evaluation poses are held out from any training set made with the same seed.

Every benchmark draws through `eval_rng`. Levels and adaptation share the default stream; a benchmark with a
`Stream` of its own (reaching) puts its word second, so its draws never coincide with another benchmark's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

EVAL_STREAM = 0xB0D7_E7A1          # first entropy word of every evaluation seed sequence
PURPOSE = {"targets": 0, "beliefs": 1, "noise": 2, "starts": 3}


@dataclass(frozen=True)
class Stream:
    """A benchmark's own seed stream: its entropy word (second, after EVAL_STREAM) and its purposes' codes."""

    word: int
    purposes: Mapping[str, int]


REACHING = Stream(0x4EAC_4100, {"targets": 0, "starts": 1, "noise": 2, "cue": 3, "imagined": 4})


def eval_rng(seed: int, run: int | None, purpose: str, *keys: int, stream: Stream | None = None
             ) -> np.random.Generator:
    """The generator of one evaluation run for one purpose and extra keys:
    `SeedSequence([EVAL_STREAM, (stream.word,) seed, (run,) purpose, *keys])`. run None: a benchmark with one run
    per seed (reaching), whose sequences have no run word."""
    purposes = PURPOSE if stream is None else stream.purposes
    words = [EVAL_STREAM, *([] if stream is None else [stream.word]), int(seed),
             *([] if run is None else [int(run)]), purposes[purpose], *map(int, keys)]
    return np.random.default_rng(np.random.SeedSequence(words))
