"""`generate(config)`: a sharded, deterministic, resumable dataset job (joblib loky or Ray).

N samples are split into fixed-size shards, each sampled, observed and written by whichever worker runs it
(`shards`: the split and one shard's work, deterministic for any workers and backend); the root attr
`complete=True` is written last, once every shard's done marker holds its checksum. Rerunning skips
done shards and rewrites those whose chunks are missing, unreadable or differ from their checksum (`integrity`).
Before anything is built or written, `guards` checks the output folder, the shard count, disk, memory and
(with images) rendering, and a babbling run simulates one probe episode (a diverging simulation is an error). Then
the backend comes up (a Ray cluster that does not answer fails here), and the run holds the store's lock
(`locks.store_lock`) from before it looks at the store until it is complete: one datagen run per store.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import tempfile
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from bodyschema import log
from bodyschema.base.locks import store_lock
from bodyschema.datagen.backends import Runner, backend
from bodyschema.datagen.body.attrs import camera_attrs, robot_attrs
from bodyschema.datagen.body.infer import check_view
from bodyschema.datagen.body.reach import arm_reach
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.guards import check_resources, check_writable, n_shards, probe_render
from bodyschema.datagen.samplers import Babbler
from bodyschema.datagen.shards import chunk_len, plan_shards, release_robots, run_shard, sampling_ranges
from bodyschema.datagen.store.integrity import data_arrays, failing_shards
from bodyschema.datagen.store.schema import (
    SCHEMA_VERSION,
    StoreWriteError,
    create_store,
    drop_shard_marks,
    features,
    has_done_markers,
    mark_complete,
    now,
    open_store,
    reset_done_markers,
    shards_done,
    versions,
)
from bodyschema.errors import must_be

logger = logging.getLogger(__name__)
PROBE_SAMPLES = 200  # babbling: samples of the probe episode simulated before anything is written (~10 s of motion)


def _attrs(config: DatagenConfig, robot: Robot, ranges: np.ndarray, shards: int, feats: dict) -> dict:
    base, reach = arm_reach(robot.model, robot.ee_site)  # the bounds validate_store checks ee_xyz, jacobian against
    if config.sampler == "uniform":
        params = {"low": ranges[:, 0].tolist(), "high": ranges[:, 1].tolist(), "touch": "at rest at q"}
    elif config.sampler == "gaussian":
        params = {"mean": ranges.mean(axis=1).tolist(), "std": (np.diff(ranges, axis=1)[:, 0] / 6).tolist(),
                  "clip": ranges.tolist(), "touch": "at rest at q"}
    else:
        b = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, config.record_hz, config.hold_s)
        params = {"targets": "uniform in sampling_ranges", "hold_s": list(config.hold_s),
                  "record_hz": config.record_hz, "rate_hz": b.rate_hz, "stride_steps": b.stride,
                  "timestep_s": float(robot.model.opt.timestep), "episode_len": config.episode_len(),
                  "n_episodes": -(-config.n // config.episode_len()), "actuators": "position",
                  "gravity_m_s2": float(-robot.model.opt.gravity[2]), "start": "at rest, uniform in sampling_ranges",
                  "touch": "simulated contact force at the recorded instant",
                  "target": "the servo targets the arm is driven toward from each recorded sample on (the commands)"}
    return {"schema_version": SCHEMA_VERSION, "robot": robot.name, "mjcf_sha256": robot.mjcf_sha256,
            "dq": robot.dq, "joint_names": list(robot.joint_names), "joint_limits": robot.joint_limits.tolist(),
            "sampling_ranges": ranges.tolist(),
            "workspace": None if config.ranges is not None else config.workspace_name,  # None: explicit ranges
            **camera_attrs(robot),
            "image_size": list(robot.image_size), "channels": robot.channels, "images": config.images,
            "sampler": config.sampler, "sampler_params": params, "seed": config.seed, "config": config.to_dict(),
            "versions": versions(), "created_at": now(), "n": config.n, "chunk_len": chunk_len(config),
            "n_shards": shards, "features": feats, "reach_m": reach, "base_m": base.tolist(),
            **robot_attrs(robot)}  # the record and the model file: the store rebuilds its robot (Robot.from_attrs)


def probe_babble(config: DatagenConfig, robot: Robot, ranges: np.ndarray) -> None:
    """Simulate one short episode as shard 0 starts, so a diverging simulation fails before a store exists."""
    babbler = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, config.record_hz, config.hold_s)
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, 0]))
    babbler.episode(rng, ranges, min(config.episode_len(), PROBE_SAMPLES))


def _check_location(path: Path) -> None:
    """Fail before any work when the output cannot be written (disk space is checked earlier, in guards)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=".bodyschema-probe-"):
            pass
    except OSError as e:
        raise StoreWriteError.from_os_error(path, e) from e


def _prepare(path: Path, config: DatagenConfig, feats: dict, attrs: dict) -> None:
    """Resume a store made with the same config, replace it with --overwrite, or refuse; else create it."""
    if path.exists() and not (path / "zarr.json").exists():
        if not (path.is_dir() and not any(path.iterdir())):
            raise FileExistsError(must_be("out", "a new path, an empty directory or a bodyschema store",
                                          str(path), "Choose another --out; nothing was deleted."))
        path.rmdir()
    if path.exists():
        old = dict(open_store(path).attrs)
        if "schema_version" not in old or "config" not in old:
            raise FileExistsError(must_be("out", "a new path or a bodyschema store", f"another Zarr store at {path}",
                                          "Choose another --out; nothing was deleted."))
        if config.overwrite:
            try:
                shutil.rmtree(path)
            except OSError as e:
                raise StoreWriteError.from_os_error(path, e) from e
        else:
            old_id = {k: v for k, v in old.get("config", {}).items() if k in config.identity()}
            if old_id != config.identity():
                diff = sorted(k for k in config.identity() if old_id.get(k) != config.identity()[k])
                raise FileExistsError(must_be("out", "a new path or a store made with the same config",
                                              f"a store at {path} made with a different config (differs in {diff})",
                                              "Pass --overwrite to replace it, or choose another --out."))
            if old["schema_version"] != SCHEMA_VERSION:  # schema 1 recorded no shard checksums: cannot be checked
                raise FileExistsError(must_be("out", f"a store of schema {SCHEMA_VERSION} to resume",
                                              f"schema {old['schema_version']} at {path}",
                                              "Pass --overwrite to regenerate it (same config, same data)."))
            lost = sorted(set(feats) - set(data_arrays(open_store(path))))
            if lost:  # a whole array gone, or one an older datagen did not write: no shard can be written into it
                older = set(lost) - set(old.get("features") or {})
                why = f" (made before datagen wrote {sorted(older)})" if older else ""
                raise FileExistsError(must_be("out", "a store holding every array of its schema",
                                              f"{lost} missing{why}",
                                              "Pass --overwrite to regenerate it (same config, same data)."))
            if old.get("created"):
                _restore_markers(path, attrs["n_shards"])
                return  # resume
    try:
        create_store(path, feats, config.n, chunk_len(config), attrs["n_shards"], attrs)
    except OSError as e:
        raise StoreWriteError.from_os_error(path, e) from e


def _restore_markers(path: Path, shards: int) -> None:
    """A store whose `shard_done` was deleted or replaced has no checksums to trust: every shard is rewritten."""
    root = open_store(path, mode="r+")
    if has_done_markers(root, shards):
        return
    logger.warning(f"datagen: {path} lost its shard checksums (shard_done): rewriting every shard")
    try:
        reset_done_markers(root, shards)
    except OSError as e:
        raise StoreWriteError.from_os_error(path, e) from e


def _repair(path: Path, root) -> None:
    """Forget the done shards whose chunks are missing, unreadable or differ from their checksum: they rerun."""
    faults = failing_shards(path, root)
    if faults:
        try:
            drop_shard_marks(root, sorted(faults))
        except OSError as e:
            raise StoreWriteError.from_os_error(path, e) from e
        logger.warning(f"datagen: rewriting {len(faults)} damaged shard(s) of {path}: "
                       + ", ".join(f"{i} ({why})" for i, why in sorted(faults.items())[:10]))


def generate(config: DatagenConfig, progress: bool = False) -> Path:
    """Write (or finish) the dataset described by `config`; returns the store path once it is complete."""
    path = config.store_path.resolve()  # absolute: Ray workers do not share the driver's working directory
    with contextlib.ExitStack() as stack:
        with log.phase("datagen: checking robot, camera and disk, starting workers", progress):   # ~2–6 s
            feats, attrs = _checked(config, path)
            run_jobs = stack.enter_context(backend(config.backend, config.workers))   # up (or refused) before
            _check_location(path)                                                     # anything is created
        with store_lock(path):
            try:
                _run(path, config, feats, attrs, run_jobs, progress)
            finally:
                release_robots()
    return path


def _checked(config: DatagenConfig, path: Path) -> tuple[dict, dict]:
    """The store's features and attributes, once every check that needs no write has passed."""
    check_writable(path)  # creates nothing; a read-only or pseudo file system (/proc, /sys) is named as such
    robot = Robot.load(config.robot, image_size=config.image_size, rgb=config.rgb, gravity=config.gravity)
    try:
        ranges = sampling_ranges(config, robot)
        image_shape = (*robot.image_size, 3) if robot.channels == 3 else tuple(robot.image_size)
        feats = features(robot.dq, image_shape if config.images else None, robot.sensors, not config.kinematic)
        check_resources(config, feats, chunk_len(config), path)  # O(1): before any per-shard list or any write
        attrs = _attrs(config, robot, ranges, n_shards(config, chunk_len(config)), feats)
        if not config.kinematic:
            probe_babble(config, robot, ranges)
        if config.images:
            check_view(robot, ranges)  # a camera that hardly sees the ee: the house error, before any write
            probe_render(robot)  # an unusable MUJOCO_GL fails here, not as a store full of NaN
            report_observability(robot, ranges)
    finally:
        robot.close()
    return feats, attrs


def report_observability(robot: Robot, ranges: np.ndarray) -> None:
    """Log each camera's observability table (pixels changed, ee mm per degree of each joint) and a house warning
    per joint no camera sees: a warning, not an error (the store is still worth making for the joints it sees)."""
    from bodyschema.datagen.body.observability import every_camera, unseen_warnings
    views = every_camera(robot, ranges)
    for seen in views:
        logger.info(seen.table())
    for warning in unseen_warnings(views):
        logger.warning(warning)


def _run(path: Path, config: DatagenConfig, feats: dict, attrs: dict, run_jobs: Runner, progress: bool) -> None:
    """Under the store's lock: create or resume the store, run the shards not done, then mark it complete."""
    shards = plan_shards(config)
    _prepare(path, config, feats, attrs)
    root = open_store(path, mode="r+")
    _repair(path, root)
    done, config_dict = shards_done(root), config.to_dict()
    jobs = [(str(path), config_dict, s) for s in shards if not done[s.index]]
    with tqdm(total=len(shards), initial=len(shards) - len(jobs), unit="shard", disable=not progress,
              desc=f"datagen {config.robot}/{config.sampler} -> {path.name}") as bar:
        if jobs:
            run_jobs(run_shard, jobs, bar.update)
    root = open_store(path, mode="r+")
    missing = np.flatnonzero(~shards_done(root))
    if missing.size:
        raise RuntimeError(must_be("every shard", "done after the run", f"shards {missing[:20].tolist()} not done",
                                   "Rerun the same command to resume."))
    if not root.attrs.get("complete"):
        try:
            mark_complete(root)
        except OSError as e:
            raise StoreWriteError.from_os_error(path, e) from e
