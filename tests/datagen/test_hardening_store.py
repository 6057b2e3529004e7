"""Damaged stores are found and repaired; oversized jobs and broken rendering are refused before anything is written.

Each damage once seen by a user: a deleted chunk (read back as zeros, `validate` passed), a truncated chunk (a Zstd
RuntimeError traceback on rerun), a flipped byte, a value changed after writing. `validate_store` names it, the same
`datagen` command rewrites only the damaged shard, and the store is then byte-identical to one never damaged.
"""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import zarr

import bodyschema.datagen.generate as gen
import bodyschema.datagen.guards as guards
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.validate import validate_store

JOB = dict(robot="planar2", n=40, shard_size=16, seed=4)  # 3 shards of rendered frames, the last one partial


def files(path) -> dict[str, bytes]:
    """Every file of a store but the root zarr.json (its attrs hold creation times)."""
    return {p.relative_to(path).as_posix(): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file() and p != path / "zarr.json"}


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return generate(DatagenConfig(**JOB, out=tmp_path_factory.mktemp("clean") / "s.zarr"), progress=False)


def delete(path):
    (path / "image" / "c" / "1" / "0" / "0").unlink()


def truncate(path):
    chunk = path / "q" / "c" / "2" / "0"  # the partial last shard: zarr would merge into the damaged chunk
    chunk.write_bytes(chunk.read_bytes()[:5])


def flip(path):
    chunk = path / "jacobian" / "c" / "0" / "0" / "0"
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0xFF
    chunk.write_bytes(bytes(data))


def change(path):
    root = zarr.open_group(str(path), mode="r+")
    root["q"][20] = root["q"][20] * np.float32(0.5)  # a plausible pose, but not the one written


def marker(path):
    (path / "shard_done" / "c" / "1").write_bytes(b"\x01\x02\x03")  # a torn 8-byte checksum


DAMAGES = {delete: (1, "image chunks must be on disk"), truncate: (2, "q rows 32:40 must be readable"),
           flip: (0, "jacobian rows 0:16 must be readable"), change: (1, "checksum in its shard_done marker"),
           marker: (1, "shard_done must be readable")}


@pytest.mark.parametrize("damage", DAMAGES, ids=lambda f: f.__name__)
def test_a_damaged_shard_is_reported_then_rewritten_to_the_clean_bytes(clean, tmp_path, damage, caplog):
    shard, words = DAMAGES[damage]
    path = shutil.copytree(clean, tmp_path / "s.zarr")
    damage(path)
    problems = validate_store(path)
    assert len(problems) == 1 and words in problems[0] and "rewrites the damaged shards" in problems[0], problems
    before = {k: (path / k).stat().st_mtime_ns for k in files(path)}
    generate(DatagenConfig(**JOB, out=path), progress=False)  # the same command again
    if damage is not marker:  # a damaged marker reads as "not done": the shard simply reruns
        assert f"rewriting 1 damaged shard(s) of {path}: {shard} (" in caplog.text   # a logged warning
    assert validate_store(path) == []
    assert files(path) == files(clean)  # byte-identical chunks, markers and array metadata
    rewritten = {k for k in before if (path / k).stat().st_mtime_ns != before[k]}
    assert rewritten and all(f"/c/{shard}" in k for k in rewritten), rewritten  # only the damaged shard's chunks


def test_a_store_that_lost_a_whole_array_is_refused_not_half_repaired(clean, tmp_path):
    path = shutil.copytree(clean, tmp_path / "s.zarr")
    shutil.rmtree(path / "jacobian")
    with pytest.raises(FileExistsError, match=r"out must be a store holding every array.*'jacobian'.*--overwrite"):
        generate(DatagenConfig(**JOB, out=path), progress=False)
    generate(DatagenConfig(**JOB, out=path, overwrite=True), progress=False)
    assert validate_store(path) == [] and files(path) == files(clean)


def test_a_trillion_samples_is_refused_before_any_list_or_write(tmp_path, monkeypatch):
    def no_list(config):
        raise AssertionError("the shard list was built before the size check")

    monkeypatch.setattr(gen, "plan_shards", no_list)
    out = tmp_path / "new" / "big.zarr"
    with pytest.raises(ValueError, match=r"at most 100000 shards.*Raise --shard-size or lower --n"):
        generate(DatagenConfig(n=10 ** 12, out=out), progress=False)  # 512-row shards: 2e9 of them
    with pytest.raises(OSError, match=r"free space at the output location must be >= 41\d{8}\.0 MB"):
        generate(DatagenConfig(n=10 ** 12, shard_size=10 ** 8, out=out), progress=False)  # 4 PB of 64x64 frames
    assert not (tmp_path / "new").exists()


def test_shards_too_big_for_memory_are_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(guards, "available_memory", lambda: 50_000_000)  # 50 MB
    with pytest.raises(ValueError, match=r"memory for the shards in flight.*Lower --shard-size or --workers"):
        generate(DatagenConfig(n=4096, shard_size=2048, workers=2, out=tmp_path / "m.zarr"), progress=False)
    assert not (tmp_path / "m.zarr").exists()
    assert guards.sample_bytes({"image": {"dtype": "uint8", "shape": [64, 64]}}) == 4096


def test_a_render_failure_is_refused_before_the_store_exists(tmp_path, monkeypatch):
    import mujoco

    def no_gl(self, q):
        raise mujoco.FatalError("an OpenGL platform library has not been loaded into this process")

    monkeypatch.setattr(gen.Robot, "render", no_gl)
    with pytest.raises(OSError, match=r"rendering \(MUJOCO_GL=.*\) must be a working OpenGL backend.*--no-images"):
        generate(DatagenConfig(n=32, out=tmp_path / "r.zarr"), progress=False)
    assert not (tmp_path / "r.zarr").exists()
    generate(DatagenConfig(n=32, images=False, out=tmp_path / "k.zarr"), progress=False)  # no rendering needed


def test_the_cli_with_an_unusable_mujoco_gl_leaves_no_nan_store(tmp_path):
    pytest.importorskip("glfw")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["MUJOCO_GL"] = "glfw"  # a windowing backend without a display: no GL context
    out = tmp_path / "d.zarr"
    run = subprocess.run([sys.executable, "-m", "bodyschema.cli", "datagen", "--n", "16", "--out", str(out)],
                         env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr
    assert "rendering (MUJOCO_GL='glfw') must be a working OpenGL backend" in run.stderr
    assert "Traceback" not in run.stderr and not out.exists()
