"""Small stores for the export tests: a babbling one (episodes, time, servo targets, RGB images, several shards), a
uniform one (independent poses, no images), a babbling one as datagen wrote it before it recorded targets, and a
babbling one's LeRobot export as another tool would have written it."""

from __future__ import annotations

import shutil
from pathlib import Path

import zarr

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.integrity import shard_digest
from bodyschema.datagen.store.schema import mark_shard_done


def babble_store(folder: Path) -> Path:
    """planar2, 150 samples in 4 episodes of 2 s at 20 Hz, 64-row shards, 24×32 RGB images."""
    return generate(DatagenConfig(robot="planar2", n=150, sampler="babble", episode_s=2.0, shard_size=64,
                                  image_size=(24, 32), rgb=True, out=folder / "babble.zarr"))


def foreign_lerobot(folder: Path, name: str = "lerobot") -> tuple[Path, Path]:
    """(babble_store, its LeRobot export at folder/name) with meta/bodyschema.json removed: no units, body or attrs,
    a dataset as another tool wrote it."""
    store = babble_store(folder)
    out = export_dataset(store, folder / name, "lerobot")
    (out / "meta" / "bodyschema.json").unlink()
    return store, out


def uniform_store(folder: Path) -> Path:
    """planar2, 40 independent poses, kinematics only."""
    return generate(DatagenConfig(robot="planar2", n=40, images=False, out=folder / "uniform.zarr"))


def older_store(store: Path, out: Path) -> Path:
    """A copy of the babbling `store` as datagen wrote it before it recorded the servo targets and the ee's
    orientation: no `target` or `ee_rot` array, no feature or sampler_params entry of them, and shard checksums over
    the arrays left. The other arrays are what that datagen wrote (recording either draws no random number: same
    seed, same bytes, checked when each was added)."""
    shutil.copytree(store, out)
    root = zarr.open_group(str(out), mode="r+")
    newer = ("target", "ee_rot")
    for name in newer:
        del root[name]
    attrs = dict(root.attrs)
    root.attrs["features"] = {k: v for k, v in attrs["features"].items() if k not in newer}
    root.attrs["sampler_params"] = {k: v for k, v in attrs["sampler_params"].items() if k not in newer}
    step, n = attrs["chunk_len"], attrs["n"]
    for shard, start in enumerate(range(0, n, step)):
        mark_shard_done(root, shard, shard_digest(root, start, min(n, start + step)))
    return out
