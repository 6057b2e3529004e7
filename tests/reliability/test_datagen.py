"""Issue 25, datagen: one run per store, bounded work, bad data refused, conflicting flags and tracebacks gone.

Each test reproduces a defect the round-3 probe found (named in its docstring) and checks the property that now
holds. The CLI-level bad inputs extend tests/test_cli_fuzz.py's harness: one line per case in CASES.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zarr

import bodyschema.datagen.generate as gen
from bodyschema.base.locks import Locked, lock_path, store_lock
from bodyschema.base.ray_session import check_reachable
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig, max_workers
from bodyschema.datagen.generate import generate
from bodyschema.datagen.samplers import Babbler
from bodyschema.datagen.store.integrity import shard_digest
from bodyschema.datagen.store.schema import DONE, mark_shard_done
from bodyschema.datagen.store.validate import validate_store
from tests.test_cli_fuzz import build_world, check_clear_failure, run_in_process, snapshot

KINEMATIC = dict(robot="planar2", n=48, shard_size=16, images=False, seed=3)  # 3 shards, no rendering: ~1 s
BABBLE = dict(robot="planar2", n=60, shard_size=20, images=False, sampler="babble", episode_s=1.0, seed=5)


def arrays(path: Path) -> dict[str, bytes]:
    root = zarr.open_group(str(path), mode="r")
    return {name: np.asarray(root[name][:]).tobytes() for name in sorted(root.array_keys()) if name != DONE}


@pytest.fixture(scope="module")
def stores(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("stores")
    return {"planar2": generate(DatagenConfig(**KINEMATIC, out=root / "planar2.zarr"), progress=False),
            "babble": generate(DatagenConfig(**BABBLE, out=root / "babble.zarr"), progress=False),
            "nao": generate(DatagenConfig(robot="nao_arm", n=16, images=False, out=root / "nao.zarr"), progress=False)}


@pytest.fixture
def copy(stores, tmp_path):
    return lambda name: shutil.copytree(stores[name], tmp_path / f"{name}.zarr")


def set_attrs(path: Path, **attrs) -> None:
    zarr.open_group(str(path), mode="r+").attrs.update(attrs)


def rewrite_as_written(path: Path, name: str, values: np.ndarray) -> None:
    """Replace array `name` and record the new checksums, as a generator writing these values would have."""
    root = zarr.open_group(str(path), mode="r+")
    root[name][:] = values
    step, n = root.attrs["chunk_len"], root.attrs["n"]
    for shard in range(root.attrs["n_shards"]):
        mark_shard_done(root, shard, shard_digest(root, shard * step, min(n, (shard + 1) * step)))


def problems_naming(path: Path, *words: str) -> list[str]:
    found = [p for p in validate_store(path) if all(w in p for w in words)]
    assert found, f"no problem naming {words}: {validate_store(path)}"
    return found


# ---- 1. one run per store -------------------------------------------------------------------------------------
def test_a_second_run_into_a_locked_store_is_refused_naming_the_holder(tmp_path):
    """Two runs into one store interleaved: a store claiming one config over another's data, exit 0."""
    out = tmp_path / "s.zarr"
    with store_lock(out):  # another open file description: flock refuses it even within this process
        with pytest.raises(Locked, match=rf"store .* must be free .* Got 'locked by pid {os.getpid()}'"):
            generate(DatagenConfig(**KINEMATIC, out=out), progress=False)
    assert not out.exists() and not lock_path(out).exists()
    generate(DatagenConfig(**KINEMATIC, out=out), progress=False)  # free again
    assert validate_store(out) == [] and not lock_path(out).exists()


def test_the_lock_file_of_a_dead_run_is_taken_over(tmp_path):
    """A run killed with -9 leaves `<store>.lock` holding its pid; flock died with it, so the next run proceeds."""
    out = tmp_path / "s.zarr"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock_path(out).write_text(f"{dead.pid}\n")
    generate(DatagenConfig(**KINEMATIC, out=out), progress=False)
    assert validate_store(out) == []


def test_two_processes_with_different_seeds_leave_one_consistent_store(tmp_path):
    """The probe's race, for real: whatever the interleaving, the store's recorded seed is the one of its data."""
    out = tmp_path / "s.zarr"
    code = ("import sys; from bodyschema.datagen.config import DatagenConfig; from bodyschema.datagen.generate import "
            "generate; generate(DatagenConfig(robot='planar2', n=48, shard_size=16, images=False, overwrite=True, "
            f"seed=int(sys.argv[1]), out={str(out)!r}), progress=False)")
    runs = [subprocess.Popen([sys.executable, "-c", code, seed], stderr=subprocess.PIPE, text=True)
            for seed in ("0", "7")]
    errors = [run.communicate(timeout=120)[1] for run in runs]
    assert any(run.returncode == 0 for run in runs), errors
    for run, err in zip(runs, errors):
        assert run.returncode == 0 or "must be free" in err, err  # refused only by the lock, never half-merged
    assert validate_store(out) == []
    seed = zarr.open_group(str(out)).attrs["seed"]
    reference = generate(DatagenConfig(**{**KINEMATIC, "seed": seed}, out=tmp_path / "ref.zarr"), progress=False)
    assert arrays(out) == arrays(reference)


# ---- 2. bounded ------------------------------------------------------------------------------------------------
def test_workers_are_bounded_by_the_cpu_count():
    """`--workers 100000` kept starting processes."""
    DatagenConfig(workers=max_workers())
    with pytest.raises(ValueError, match=rf"workers must be <= {max_workers()} .* Got 100000"):
        DatagenConfig(workers=100_000)


def test_an_unreachable_ray_address_fails_in_seconds_before_anything_is_created(tmp_path, monkeypatch):
    """RAY_ADDRESS=127.0.0.1:1 retried forever (against this machine's routable address) and left an empty store."""
    ray = pytest.importorskip("ray")

    def no_init(*args, **kwargs):
        raise AssertionError("ray.init was called for an address nothing listens on")

    monkeypatch.setattr(ray, "init", no_init)
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:1")
    out = tmp_path / "new" / "r.zarr"
    with pytest.raises(ConnectionError, match=r"RAY_ADDRESS must be a Ray cluster accepting connections within"):
        generate(DatagenConfig(**KINEMATIC, backend="ray", out=out), progress=False)
    assert not (tmp_path / "new").exists()


def test_a_listening_address_passes_the_reachability_check():
    import socket

    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        check_reachable(f"ray://127.0.0.1:{port}")  # Ray Client: dialled as given
    with pytest.raises(ConnectionError, match="RAY_ADDRESS must be"):
        check_reachable(f"ray://127.0.0.1:{port}", timeout_s=1.0)  # closed now


# ---- 3. bad data does not validate ------------------------------------------------------------------------------
def test_a_diverging_simulation_is_an_error_and_writes_no_mujoco_log(tmp_path, monkeypatch):
    """Panda babble at 1e30 m/s^2: 2 distinct poses, 8e26 rad/s, and MUJOCO_LOG.TXT in the working folder."""
    monkeypatch.chdir(tmp_path)
    robot = Robot.load("panda", gravity=1e30)
    babbler = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, 20.0, (0.2, 1.0))
    with pytest.raises(FloatingPointError, match=r"babbling simulation must be stable .*mjWARN_BADQACC"):
        babbler.episode(np.random.default_rng(0), robot.sampling_ranges, 40)
    robot.close()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_a_diverging_babble_is_refused_before_the_store_exists(tmp_path, monkeypatch):
    real_load = gen.Robot.load
    monkeypatch.setattr(gen.Robot, "load", lambda name, **kw: real_load(name, **{**kw, "gravity": 1e30}))
    out = tmp_path / "p.zarr"
    with pytest.raises(FloatingPointError, match="must be stable"):
        generate(DatagenConfig(robot="panda", n=40, sampler="babble", images=False, out=out), progress=False)
    assert not out.exists()


def test_gravity_is_physically_bounded():
    DatagenConfig(gravity=100.0, sampler="babble")
    with pytest.raises(ValueError, match=r"gravity must be a magnitude in \[0, 100\] m/s\^2"):
        DatagenConfig(gravity=1e30, sampler="babble")


def test_absurd_joint_velocities_do_not_validate(copy):
    path = copy("babble")
    qvel = np.asarray(zarr.open_group(str(path))["qvel"][:])
    qvel[7, 0] = 8e26
    rewrite_as_written(path, "qvel", qvel)
    problems_naming(path, "qvel must be |qvel| <= 1000 rad/s", "first at row 7")


@pytest.mark.parametrize("robot", ["../../x", "a/b", "", 7])
def test_a_robot_attr_that_is_a_path_or_not_a_name_does_not_validate(copy, robot):
    path = copy("planar2")
    set_attrs(path, robot=robot)
    problems_naming(path, "attrs robot must be")


def test_relabelled_nao_data_is_not_planar2(copy):
    """nao_arm data with attrs robot=planar2 validated, then became planar2's champion."""
    path = copy("nao")
    set_attrs(path, robot="planar2")
    problems_naming(path, "q's width must be planar2's joint count 2", "Got 4")


@pytest.mark.parametrize("key, value, words", [
    ("joint_limits", "wide", ("attrs joint_limits must be (2, 2) finite",)),
    ("joint_limits", [[-9.0, 9.0], [-9.0, 9.0]], ("attrs joint_limits must be planar2's",)),
    ("sampling_ranges", [[0.0, float("nan")], [0.0, 1.0]], ("attrs sampling_ranges must be",)),
    ("joint_names", ["a", "b"], ("attrs joint_names must be planar2's",)),
    ("joint_names", "shoulder", ("attrs joint_names must be 2 strings",)),
    ("mjcf_sha256", "0" * 64, ("attrs mjcf_sha256 must be the shipped planar2's",)),
    ("dq", 3, ("attrs dq must be q's width 2",)),
])
def test_attrs_of_the_wrong_type_shape_or_robot_do_not_validate(copy, key, value, words):
    path = copy("planar2")
    set_attrs(path, **{key: value})
    problems_naming(path, *words)


def test_q_beyond_the_robots_joint_limits_does_not_validate_even_with_matching_ranges(copy):
    path = copy("planar2")
    q = np.asarray(zarr.open_group(str(path))["q"][:])
    q[3, 1] = 3.0  # planar2's elbow stops at 2.6 rad
    rewrite_as_written(path, "q", q)
    set_attrs(path, sampling_ranges=[[-2.5, 2.5], [-2.5, 3.0]])  # the recorded ranges widened to match
    problems_naming(path, "q must be inside the planar2 joint limits", "first at row 3")


def test_a_store_without_its_checksums_is_reported_and_rerunning_datagen_rewrites_it(copy):
    """Deleting shard_done switched every checksum off; re-running datagen then raised KeyError."""
    path = copy("planar2")
    before = arrays(path)
    del zarr.open_group(str(path), mode="r+")[DONE]
    problems_naming(path, "shard_done must be present", "checksums missing")
    generate(DatagenConfig(**KINEMATIC, out=path), progress=False)
    assert validate_store(path) == [] and arrays(path) == before


def test_a_replaced_shard_done_is_reported_and_rerunning_datagen_rewrites_it(copy):
    path = copy("planar2")
    before = arrays(path)
    root = zarr.open_group(str(path), mode="r+")
    del root[DONE]
    root.create_array(DONE, data=np.ones(5, np.uint64), chunks=(1,))  # 5 "done" checksums for 3 shards
    problems_naming(path, "shard_done shape must be (3,)")
    generate(DatagenConfig(**KINEMATIC, out=path), progress=False)
    assert validate_store(path) == [] and arrays(path) == before


def test_a_zarr_json_that_is_not_an_object_is_named(copy):
    """`validate` on a zarr.json of `[]` said "pop expected at most 1 argument"."""
    path = copy("planar2")
    (path / "zarr.json").write_text("[]")
    assert validate_store(path) == [problems_naming(path, "zarr.json must be a JSON object", "a JSON list")[0]]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and /sys are Linux pseudo file systems")
@pytest.mark.parametrize("out", ["/proc/x.zarr", "/sys/bodyschema/x.zarr"])
def test_an_out_on_a_pseudo_file_system_is_named_not_writable(out):
    """`--out /proc/x.zarr` said "free space ... must be >= 0.0 MB"."""
    with pytest.raises(PermissionError, match=r"the folder of --out .* must be writable. Got \S/(proc|sys)"):
        generate(DatagenConfig(**KINEMATIC, out=Path(out)), progress=False)


# ---- 4. conflicting flags ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, words", [
    (dict(images=False, rgb=True), ("image flags with --no-images must be unset", "{'--rgb': True}")),
    (dict(images=False, image_size=(32, 32)), ("image flags with --no-images must be unset", "--image-size")),
    (dict(hold_s=(0.3, 0.5)), ("babbling flags with --sampler uniform must be unset", "{'--hold-s': (0.3, 0.5)}")),
    (dict(sampler="gaussian", record_hz=10.0, episode_s=5.0),
     ("babbling flags with --sampler gaussian", "{'--record-hz': 10.0, '--episode-s': 5.0}")),
])
def test_flags_the_run_would_ignore_are_refused(kwargs, words):
    """`--no-images --rgb` and babbling flags with --sampler uniform were silently accepted."""
    with pytest.raises(ValueError) as info:
        DatagenConfig(**kwargs)
    assert all(word in str(info.value) for word in words), str(info.value)


def test_the_same_flags_with_their_own_mode_are_accepted():
    DatagenConfig(rgb=True, image_size=(32, 32))
    DatagenConfig(sampler="babble", hold_s=(0.3, 0.5), record_hz=10.0, episode_s=5.0)
    DatagenConfig(images=False, sampler="gaussian")  # defaults are never a conflict


# ---- the CLI: an extended fuzz beside tests/test_cli_fuzz.py --------------------------------------------------------
CASES = [
    ("datagen-workers-huge", "datagen --workers 100000 --n 4 --no-images --out {W}/new.zarr"),
    ("datagen-gravity-huge", "datagen --robot panda --sampler babble --gravity 1e30 --n 4 --out {W}/new.zarr"),
    ("datagen-episode-inf", "datagen --sampler babble --episode-s inf --n 4 --no-images --out {W}/new.zarr"),
    ("datagen-record-hz-inf", "datagen --sampler babble --record-hz inf --n 4 --no-images --out {W}/new.zarr"),
    ("datagen-no-images-rgb", "datagen --no-images --rgb --n 4 --out {W}/new.zarr"),
    ("datagen-no-images-size", "datagen --no-images --image-size 32 32 --n 4 --out {W}/new.zarr"),
    ("datagen-uniform-hold", "datagen --hold-s 0.3 0.5 --n 4 --no-images --out {W}/new.zarr"),
    ("datagen-gaussian-record-hz", "datagen --sampler gaussian --record-hz 10 --n 4 --no-images --out {W}/new.zarr"),
    ("datagen-uniform-episode", "datagen --episode-s 5 --n 4 --no-images --out {W}/new.zarr"),
    ("datagen-out-proc", "datagen --n 4 --no-images --out /proc/x.zarr"),
    ("datagen-out-sys", "datagen --n 4 --no-images --out /sys/bodyschema/x.zarr"),
    ("datagen-out-under-a-file", "datagen --n 4 --no-images --out {W}/good.zarr/zarr.json/x.zarr"),
    ("datagen-into-list-json", "datagen --n 4 --no-images --out {W}/listjson.zarr"),
    ("validate-list-json", "validate {W}/listjson.zarr"),
    ("validate-path-robot", "validate {W}/pathrobot.zarr"),
    ("validate-relabelled", "validate {W}/relabelled.zarr"),
    ("validate-no-checksums", "validate {W}/nodone.zarr"),
]
VALIDATE_ANSWERS = {"validate-list-json", "validate-path-robot", "validate-relabelled", "validate-no-checksums"}


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    return make_world(tmp_path_factory.mktemp("fuzz25"))


def make_world(w: Path) -> Path:
    """The fuzz world plus stores with a list zarr.json, a path as robot, relabelled attrs, no checksums."""
    build_world(w)
    for name in ("listjson", "pathrobot", "relabelled", "nodone"):
        shutil.copytree(w / "good.zarr", w / f"{name}.zarr")
    (w / "listjson.zarr" / "zarr.json").write_text("[]")
    set_attrs(w / "pathrobot.zarr", robot="../../x")
    set_attrs(w / "relabelled.zarr", robot="nao_arm")
    del zarr.open_group(str(w / "nodone.zarr"), mode="r+")[DONE]
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_a_clear_error(case_id, command, in_world, capsys):
    before = snapshot(in_world)
    code, err = run_in_process(command.format(W=in_world).split(), capsys)
    if case_id in VALIDATE_ANSWERS:  # validate's "this store has problems": exit 1, each problem a house line
        assert code == 1 and " must be " in err and "Traceback" not in err, err
        assert snapshot(in_world) == before
        return
    check_clear_failure(case_id, code, err, before, snapshot(in_world), in_world)
    assert not (in_world / "MUJOCO_LOG.TXT").exists()


def test_an_unreachable_ray_address_is_a_clear_error(in_world, capsys, monkeypatch):
    pytest.importorskip("ray")
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:1")
    before = snapshot(in_world)
    argv = f"datagen --backend ray --n 4 --no-images --out {in_world}/ray/new.zarr".split()
    code, err = run_in_process(argv, capsys)
    check_clear_failure("datagen-ray-unreachable", code, err, before, snapshot(in_world), in_world)
    assert "RAY_ADDRESS must be" in err and not (in_world / "ray").exists()


@pytest.mark.parametrize("command", ["datagen --n 4 --out new.zarr", "validate good.zarr",
                                     "evaluate levels --trials 2 --runs 1 --no-mlflow --out res"])
def test_an_unknown_mujoco_gl_is_a_clear_error(in_world, command):
    """`MUJOCO_GL=bogus` was a RuntimeError traceback from mujoco's import (a fresh process: mujoco reads it once),
    in every stage that simulates or renders."""
    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG")}
    env["MUJOCO_GL"] = "bogus"
    before = snapshot(in_world)
    run = subprocess.run([sys.executable, "-m", "bodyschema.cli", *command.split()],
                         cwd=in_world, env=env, capture_output=True, text=True, timeout=120)
    check_clear_failure("datagen-mujoco-gl-bogus", run.returncode, run.stderr, before, snapshot(in_world), in_world)
    assert "MUJOCO_GL must be one of egl" in run.stderr and "osmesa" in run.stderr and "glfw" in run.stderr
