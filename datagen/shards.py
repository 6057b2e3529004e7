"""A datagen job's shards: the fixed split of N samples (`plan_shards`) and one shard's work (`run_shard`).

A shard is one Zarr chunk of rows (for babbling, whole episodes); the split depends on the config only, never on the
worker count, and shard i draws from `np.random.SeedSequence([seed, i])`, so the same config gives byte-identical
arrays for any workers and backend. `run_shard` runs in whichever process the backend gives it: that process builds
its Robot once (its GL context included), samples and observes the shard's rows, writes its chunks straight into
the store, then the shard's done marker holding its checksum. `generate` is the driver.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.samplers import Babbler, sample_kinematic
from bodyschema.datagen.store.integrity import clear_shard, shard_digest
from bodyschema.datagen.store.schema import StoreWriteError, mark_shard_done, open_store, write_shard


@dataclass(frozen=True)
class Shard:
    """Rows [start, stop) of the store; for babbling also its episodes (first index and lengths)."""

    index: int
    start: int
    stop: int
    first_episode: int = 0
    episode_lengths: tuple[int, ...] = ()


def plan_shards(config: DatagenConfig) -> list[Shard]:
    """The fixed split of N into chunk-aligned shards (depends on the config only)."""
    n = config.n
    if config.kinematic:
        size = config.shard_rows()
        return [Shard(i, s, min(n, s + size)) for i, s in enumerate(range(0, n, size))]
    ep_len = config.episode_len()
    per_shard = max(1, config.shard_rows() // ep_len)  # whole episodes per shard
    lengths = [ep_len] * (n // ep_len) + ([n % ep_len] if n % ep_len else [])
    shards = []
    for i, e0 in enumerate(range(0, len(lengths), per_shard)):
        ls = tuple(lengths[e0:e0 + per_shard])
        shards.append(Shard(i, e0 * ep_len, e0 * ep_len + sum(ls), e0, ls))
    return shards


def chunk_len(config: DatagenConfig) -> int:
    """Rows per Zarr chunk = rows per (full) shard."""
    if config.kinematic:
        return config.shard_rows()
    return max(1, config.shard_rows() // config.episode_len()) * config.episode_len()


_ROBOTS: dict[tuple, tuple[Robot, Babbler | None]] = {}  # per process: building a Robot/GL context once


def _robot(config: DatagenConfig) -> tuple[Robot, Babbler | None]:
    key = (config.robot, config.image_size, config.rgb, config.gravity, config.sampler, config.record_hz,
           config.hold_s)
    if key not in _ROBOTS:
        robot = Robot.load(config.robot, image_size=config.image_size, rgb=config.rgb, gravity=config.gravity)
        babbler = None if config.kinematic else Babbler(robot.model, list(robot.joint_names), robot.joint_limits,
                                                        config.record_hz, config.hold_s)
        _ROBOTS[key] = (robot, babbler)
    return _ROBOTS[key]


def release_robots() -> None:
    """Close the robots (GL contexts) cached in this process."""
    while _ROBOTS:
        _ROBOTS.popitem()[1][0].close()


def sampling_ranges(config: DatagenConfig, robot: Robot) -> np.ndarray:
    """(Dq, 2) rad: the config's override (checked against the MJCF limits) or its robot workspace's box."""
    if config.ranges is None:
        return np.asarray(robot.workspaces[config.workspace_name], float)
    robot.check_ranges(config.ranges)
    return np.asarray(config.ranges, float)


def run_shard(path: str, config_dict: dict, shard: Shard) -> int:
    """Sample, observe and write one shard, then its done marker with its checksum. Returns the rows written."""
    config = DatagenConfig.from_dict({**config_dict, "workers": 1})  # its bound is the driver machine's CPUs
    robot, babbler = _robot(config)
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, shard.index]))
    ranges = sampling_ranges(config, robot)
    if babbler is None:
        arrays = {"q": sample_kinematic(config.sampler, rng, ranges, robot.joint_limits, shard.stop - shard.start)}
    else:
        arrays = babbler.episodes(rng, ranges, list(shard.episode_lengths), shard.first_episode)
    observed = robot.observe(arrays["q"].astype(np.float64), image=config.images)  # q as stored (float32)
    arrays.update({k: v for k, v in observed.items() if k not in arrays})  # babbling keeps its simulated touch
    try:
        root = open_store(Path(path), mode="r+")
        clear_shard(Path(path), root, shard.index)  # a damaged leftover (killed run, repair) is never read back
        write_shard(root, shard.start, arrays)
        mark_shard_done(root, shard.index, shard_digest(root, shard.start, shard.stop))  # of the bytes as stored
    except OSError as e:  # raised here, in the worker, so a network error elsewhere is never called "disk full"
        raise StoreWriteError.from_os_error(path, e) from e
    return shard.stop - shard.start
