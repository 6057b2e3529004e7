"""`generate`: config validation, byte-identical output for any workers/backend, resume after kill -9, bad output."""

import errno
import hashlib
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import zarr

import bodyschema.datagen.generate as gen
import bodyschema.datagen.shards as shard_job
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.shards import plan_shards
from bodyschema.datagen.store.schema import DONE, is_complete
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.export_stores import older_store

SMALL = dict(robot="planar2", n=96, shard_size=16, seed=7)  # 6 shards of 16 rendered 64 x 64 frames
KILLED = dict(robot="planar2", n=480, shard_size=24, seed=11)  # 20 shards, ~3 s: time to kill it midway


def hashes(path) -> dict[str, str]:
    root = zarr.open_group(str(path), mode="r")
    return {name: hashlib.sha256(np.ascontiguousarray(root[name][:]).tobytes()).hexdigest()
            for name in sorted(root.array_keys()) if name != DONE}


def assert_same_arrays(a, b):
    ha, hb = hashes(a), hashes(b)
    assert ha.keys() == hb.keys()
    for name in ha:
        assert ha[name] == hb[name], f"array {name!r} differs between {a} and {b}"


# ---- config --------------------------------------------------------------------------------------------------
def test_config_names_what_it_received():
    cases = [(dict(robot="pr2"), "robot must be one of .* Got 'pr2'"), (dict(sampler="sobol"), "Got 'sobol'"),
             (dict(backend="dask"), "backend must be one of"), (dict(n=0), "n must be an integer >= 1. Got 0"),
             (dict(n=2.5), "Got 2.5"), (dict(workers=0), "workers must be"), (dict(seed=-1), "seed must be"),
             (dict(image_size=(4, 64)), r"image_size must be .*\[8, 1024\].* Got \(4, 64\)"),
             (dict(image_size=(64, 2000)), "Got \\(64, 2000\\)"), (dict(ranges=((1.0, 0.0),)), "ranges must be"),
             (dict(hold_s=(1.0, 0.5)), "hold_s must be"), (dict(gravity=-9.8), "gravity must be"),
             (dict(record_hz=0), "record_hz must be"), (dict(episode_s=0.01), "episode_s must be")]
    for kwargs, pattern in cases:
        with pytest.raises(ValueError, match=pattern):
            DatagenConfig(**kwargs)
    with pytest.raises(ValueError) as info:  # every problem at once
        DatagenConfig(robot="pr2", n=-1, backend="dask")
    assert str(info.value).count("must be") == 3


def test_identity_ignores_execution():
    a = DatagenConfig(workers=1, backend="loky", out="a.zarr", image_size=[32, 48])
    b = DatagenConfig(workers=2, backend="ray", out="b.zarr", overwrite=True, image_size=(32, 48))
    assert a.identity() == b.identity() and a.identity() != DatagenConfig(seed=1).identity()
    assert DatagenConfig.from_dict(a.to_dict()) == a


def test_shards_tile_the_samples_on_chunk_boundaries_whatever_the_workers():
    for cfg in (DatagenConfig(n=1000, shard_size=64), DatagenConfig(n=1000, sampler="babble", shard_size=450)):
        shards = plan_shards(cfg)
        assert shards == plan_shards(DatagenConfig(**{**cfg.to_dict(), "workers": 2}))
        assert shards[0].start == 0 and shards[-1].stop == 1000
        assert all(a.stop == b.start for a, b in zip(shards, shards[1:]))
        assert all(s.start % shard_job.chunk_len(cfg) == 0 for s in shards)
    babble = plan_shards(DatagenConfig(n=1000, sampler="babble", shard_size=450))  # 200-sample episodes
    assert [s.episode_lengths for s in babble] == [(200, 200), (200, 200), (200,)]


# ---- determinism -------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    root = tmp_path_factory.mktemp("ref")
    return {"small": generate(DatagenConfig(**SMALL, out=root / "small.zarr"), progress=False),
            "killed": generate(DatagenConfig(**KILLED, out=root / "killed.zarr"), progress=False)}


def test_same_seed_same_bytes_for_two_loky_workers(reference, tmp_path):
    path = generate(DatagenConfig(**SMALL, workers=2, out=tmp_path / "w2.zarr"), progress=False)
    assert validate_store(path) == []
    assert_same_arrays(reference["small"], path)


def test_same_seed_same_bytes_on_ray(reference, tmp_path):
    pytest.importorskip("ray")
    path = generate(DatagenConfig(**SMALL, workers=2, backend="ray", out=tmp_path / "ray.zarr"), progress=False)
    assert_same_arrays(reference["small"], path)


def test_another_seed_gives_other_data(reference, tmp_path):
    path = generate(DatagenConfig(**{**SMALL, "seed": 8}, images=False, out=tmp_path / "s8.zarr"), progress=False)
    assert hashes(path)["q"] != hashes(reference["small"])["q"]


def test_babbling_store_is_valid_and_worker_independent(tmp_path):
    cfg = dict(robot="planar2", n=250, sampler="babble", episode_s=2.0, record_hz=25.0, shard_size=100,
               images=False, seed=2)
    one = generate(DatagenConfig(**cfg, out=tmp_path / "b1.zarr"), progress=False)
    two = generate(DatagenConfig(**cfg, workers=2, out=tmp_path / "b2.zarr"), progress=False)
    assert validate_store(one) == [] and validate_store(two) == []
    assert_same_arrays(one, two)
    root = zarr.open_group(str(one), mode="r")
    episode, t = root["episode"][:], root["t"][:]
    assert np.array_equal(np.unique(episode), np.arange(5)) and (np.diff(episode) >= 0).all()  # 50 + 50 + ... 50
    assert np.array_equal(np.flatnonzero(t == 0), np.arange(0, 250, 50))
    assert root.attrs["sampler_params"]["rate_hz"] == pytest.approx(25.0)
    assert root["target"].shape == root["q"].shape and root["target"].dtype == np.float32   # the servo targets
    assert root["target"].attrs["unit"] == "rad" and root.attrs["features"]["target"]["unit"] == "rad"
    poses = generate(DatagenConfig(robot="planar2", n=20, images=False, out=tmp_path / "u.zarr"), progress=False)
    assert "target" not in zarr.open_group(str(poses), mode="r").array_keys()       # no commands: none stored


# ---- resume --------------------------------------------------------------------------------------------------
def n_done(path) -> int:
    chunks = path / DONE / "c"
    return len(list(chunks.iterdir())) if chunks.exists() else 0


def test_resume_after_kill_9_gives_the_uninterrupted_bytes(reference, tmp_path, monkeypatch):
    out = tmp_path / "killed.zarr"
    code = ("from bodyschema.datagen.config import DatagenConfig; from bodyschema.datagen.generate import generate; "
            f"generate(DatagenConfig(**{KILLED!r}, out={str(out)!r}), progress=False)")
    proc = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.monotonic() + 60
    while n_done(out) < 3:
        assert proc.poll() is None, "the job ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done_before = set(np.flatnonzero(zarr.open_group(str(out), mode="r")[DONE][:]).tolist())
    assert 3 <= len(done_before) < 20 and not is_complete(out)
    assert any("complete" in p for p in validate_store(out))

    ran = []
    real = gen.run_shard
    monkeypatch.setattr(gen, "run_shard", lambda path, cfg, shard: ran.append(shard.index) or real(path, cfg, shard))
    generate(DatagenConfig(**KILLED, out=out), progress=False)  # the same command again
    assert sorted(ran) == sorted(set(range(20)) - done_before)  # done shards skipped, none run twice
    assert validate_store(out) == []
    assert_same_arrays(reference["killed"], out)


def test_rerunning_a_complete_store_does_nothing(reference):
    chunk = reference["small"] / "q" / "c" / "0" / "0"
    before = chunk.stat().st_mtime_ns
    generate(DatagenConfig(**SMALL, workers=2, out=reference["small"]), progress=False)
    assert chunk.stat().st_mtime_ns == before


# ---- refusal and bad output locations ---------------------------------------------------------------------------
def test_a_store_with_another_config_is_refused_unless_overwrite(tmp_path):
    out = tmp_path / "d.zarr"
    generate(DatagenConfig(n=16, shard_size=16, images=False, out=out), progress=False)
    first = hashes(out)["q"]
    with pytest.raises(FileExistsError, match=r"differs in \['seed'\].*--overwrite"):
        generate(DatagenConfig(n=16, shard_size=16, images=False, seed=1, out=out), progress=False)
    assert hashes(out)["q"] == first
    generate(DatagenConfig(n=16, shard_size=16, images=False, seed=1, out=out, overwrite=True), progress=False)
    assert hashes(out)["q"] != first and validate_store(out) == []


def test_a_babbling_store_made_before_targets_were_recorded_is_refused_unless_overwrite(tmp_path):
    config = DatagenConfig(robot="planar2", n=40, sampler="babble", episode_s=1.0, images=False,
                           out=tmp_path / "new.zarr")
    old = older_store(generate(config, progress=False), tmp_path / "old.zarr")
    again = DatagenConfig(**{**config.to_dict(), "out": old})
    missing = r"\['ee_rot', 'target'\] missing \(made before datagen wrote.*--overwrite"
    with pytest.raises(FileExistsError, match=missing):
        generate(again, progress=False)                      # no shard could be written into the missing array
    generate(DatagenConfig(**{**again.to_dict(), "overwrite": True}), progress=False)
    assert validate_store(old) == [] and hashes(old) == hashes(config.out)        # the same q, now with targets


def test_a_foreign_directory_is_never_deleted(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("precious")
    with pytest.raises(FileExistsError, match="nothing was deleted"):
        generate(DatagenConfig(n=8, images=False, out=tmp_path / "mine", overwrite=True), progress=False)
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "precious"


def test_ranges_outside_the_joint_limits_are_refused(tmp_path):
    with pytest.raises(ValueError, match="inside the joint limits"):
        generate(DatagenConfig(n=8, ranges=((-3.0, 0.0), (0.0, 1.0)), out=tmp_path / "r.zarr"), progress=False)


def test_unwritable_output_fails_before_any_work(tmp_path):
    (tmp_path / "a_file").write_text("")
    with pytest.raises(OSError, match="--out .* must be writable"):
        generate(DatagenConfig(n=8, out=tmp_path / "a_file" / "d.zarr"), progress=False)


def test_full_disk_fails_before_any_work(tmp_path, monkeypatch):
    monkeypatch.setattr(gen.shutil, "disk_usage", lambda p: type("U", (), {"free": 1000})())
    with pytest.raises(OSError, match="free space at the output location must be"):
        generate(DatagenConfig(n=64, out=tmp_path / "d.zarr"), progress=False)
    assert not (tmp_path / "d.zarr").exists()


def test_disk_full_midway_leaves_an_incomplete_store_that_resumes(tmp_path, monkeypatch):
    out = tmp_path / "d.zarr"
    cfg = DatagenConfig(n=64, shard_size=16, images=False, out=out)
    real, calls = shard_job.write_shard, []

    def write_then_fail(root, start, arrays):
        calls.append(start)
        if len(calls) > 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(root, start, arrays)

    monkeypatch.setattr(shard_job, "write_shard", write_then_fail)
    with pytest.raises(OSError, match="output location must be writable.*No space left"):
        generate(cfg, progress=False)
    assert not is_complete(out) and any("complete" in p for p in validate_store(out))
    monkeypatch.setattr(shard_job, "write_shard", real)
    generate(cfg, progress=False)
    assert validate_store(out) == []


def test_an_empty_directory_is_used_and_another_zarr_store_is_not_replaced(tmp_path):
    (tmp_path / "empty.zarr").mkdir()
    assert validate_store(generate(DatagenConfig(n=8, images=False, out=tmp_path / "empty.zarr"), progress=False)) == []
    zarr.open_group(str(tmp_path / "other.zarr"), mode="w", zarr_format=3).create_array("x", shape=(3,), dtype="f4")
    with pytest.raises(FileExistsError, match="another Zarr store"):
        generate(DatagenConfig(n=8, images=False, out=tmp_path / "other.zarr", overwrite=True), progress=False)
    assert "x" in zarr.open_group(str(tmp_path / "other.zarr"), mode="r").array_keys()
