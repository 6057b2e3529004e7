"""Small stores for the export tests: a babbling one (episodes, time, RGB images, several shards) and a uniform one
(independent poses, no images)."""

from __future__ import annotations

from pathlib import Path

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate


def babble_store(folder: Path) -> Path:
    """planar2, 150 samples in 4 episodes of 2 s at 20 Hz, 64-row shards, 24×32 RGB images."""
    return generate(DatagenConfig(robot="planar2", n=150, sampler="babble", episode_s=2.0, shard_size=64,
                                  image_size=(24, 32), rgb=True, out=folder / "babble.zarr"))


def uniform_store(folder: Path) -> Path:
    """planar2, 40 independent poses, kinematics only."""
    return generate(DatagenConfig(robot="planar2", n=40, images=False, out=folder / "uniform.zarr"))
