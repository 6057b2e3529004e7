"""`validate_store` catches each kind of damage (one test per kind) and reports all of them at once.

Damage to values comes two ways: a chunk changed after it was written (its shard's checksum no longer matches), or
a generator that wrote impossible values with a matching checksum (`rewrite(..., as_written=True)`): the value
checks must catch the second kind on their own.
"""

import json
import shutil

import cv2
import numpy as np
import pytest
import zarr

from bodyschema.datagen.body.camera import project
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.contact_sheet import write_contact_sheet
from bodyschema.datagen.store.integrity import shard_digest
from bodyschema.datagen.store.schema import mark_shard_done
from bodyschema.datagen.store.validate import summarize_store, validate_store
from tests.datagen.export_stores import older_store


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    out = tmp_path_factory.mktemp("valid") / "planar2.zarr"
    return generate(DatagenConfig(robot="planar2", n=48, shard_size=16, seed=3, out=out), progress=False)


@pytest.fixture
def copy(valid, tmp_path):
    return shutil.copytree(valid, tmp_path / "copy.zarr")


def rewrite(path, name, rows: slice, values, as_written=True):
    """Write `values` at `rows` of array `name`; as_written: also record the touched shards' new checksums."""
    root = zarr.open_group(str(path), mode="r+")
    root[name][rows] = values
    step, n = root.attrs["chunk_len"], root.attrs["n"]
    for shard in range(rows.start // step, (rows.stop - 1) // step + 1) if as_written else ():
        mark_shard_done(root, shard, shard_digest(root, shard * step, min(n, (shard + 1) * step)))


def one_problem(path, *words):
    problems = validate_store(path)
    assert len(problems) == 1, problems
    for word in words:
        assert word in problems[0], problems
    return problems[0]


def test_a_generated_store_is_valid(valid):
    assert validate_store(valid) == []


def test_stored_pixels_are_the_projection_of_stored_positions(valid):
    root = zarr.open_group(str(valid), mode="r")
    K, E = np.array(root.attrs["intrinsics"]), np.array(root.attrs["extrinsics"])
    uv = project(K, E, root["ee_xyz"][:].astype(float))
    assert np.abs(uv - root["ee_pixel"][:]).max() < 1e-3
    h, w = root.attrs["image_size"]
    assert ((uv >= 0) & (uv <= [w - 1, h - 1])).all()  # the camera sees the hand in every sample


def test_missing_array(copy):
    shutil.rmtree(copy / "jacobian")
    one_problem(copy, "'jacobian'", "missing")


def test_first_axes_disagree(copy):
    zarr.open_group(str(copy), mode="r+")["ee_xyz"].resize((40, 3))
    one_problem(copy, "first axis", "ee_xyz", "n=48")


def test_nan_in_a_float_array(copy):
    rewrite(copy, "q", slice(5, 6), np.nan)
    one_problem(copy, "q must be finite", "first at row 5")


def test_q_outside_the_recorded_ranges(copy):
    root = zarr.open_group(str(copy), mode="r")
    q = root["q"][7:8]
    q[0, 0] = root.attrs["sampling_ranges"][0][1] + 0.01
    rewrite(copy, "q", slice(7, 8), q)
    one_problem(copy, "q must be inside the recorded sampling_ranges", "first at row 7")


def test_ee_pixel_shifted_from_the_projection(copy):
    rewrite(copy, "ee_pixel", slice(10, 12), zarr.open_group(str(copy))["ee_pixel"][10:12] + np.float32(0.5))
    one_problem(copy, "ee_pixel must be ee_xyz projected", "2 rows", "first at row 10")


def test_a_huge_jacobian_is_beyond_the_arms_reach(copy):
    rewrite(copy, "jacobian", slice(20, 21), np.float32(3e38))  # finite, but no arm moves 3e38 m per rad
    problem = one_problem(copy, "jacobian must be columns of norm <= the arm's reach", "first at row 20")
    reach = zarr.open_group(str(copy)).attrs["reach_m"]
    assert f"{reach:.4f} m/rad" in problem and 0.5 < reach < 0.6  # planar2: links 0.3 + 0.25 m (+ hand)


def test_a_huge_jacobian_changed_after_writing_also_breaks_its_shards_checksum(copy):
    rewrite(copy, "jacobian", slice(20, 21), np.float32(3e38), as_written=False)
    problems = validate_store(copy)
    assert len(problems) == 2, problems
    assert any("jacobian must be columns of norm" in p for p in problems)
    assert any("checksum" in p and "shards [1]" in p for p in problems)


def test_ee_xyz_beyond_the_arms_reach(copy):
    xyz = zarr.open_group(str(copy))["ee_xyz"][30:31]
    rewrite(copy, "ee_xyz", slice(30, 31), xyz * 3)
    problems = validate_store(copy)
    assert any("ee_xyz must be within the arm's reach" in p and "first at row 30" in p for p in problems), problems


def test_negative_touch(tmp_path):
    path = generate(DatagenConfig(robot="panda", n=32, shard_size=16, images=False, out=tmp_path / "t.zarr"),
                    progress=False)
    assert validate_store(path) == []
    rewrite(path, "touch", slice(3, 4), -1.0)
    one_problem(path, "touch must be >= 0", "first at row 3")


@pytest.fixture(scope="module")
def babble(tmp_path_factory):
    out = tmp_path_factory.mktemp("babble") / "planar2.zarr"
    return generate(DatagenConfig(robot="planar2", n=40, sampler="babble", episode_s=1.0, shard_size=20, images=False,
                                  out=out), progress=False)


def test_babbling_targets_outside_the_joint_limits(babble, tmp_path):
    path = shutil.copytree(babble, tmp_path / "b.zarr")
    root = zarr.open_group(str(path), mode="r")
    target = root["target"][25:26]
    target[0, 1] = root.attrs["joint_limits"][1][0] - 0.1                 # no servo can be sent there
    rewrite(path, "target", slice(25, 26), target)
    one_problem(path, "target must be inside the planar2 joint limits", "1 rows, first at row 25")


def test_babbling_targets_of_the_wrong_width(babble, tmp_path):
    path = shutil.copytree(babble, tmp_path / "b.zarr")
    root = zarr.open_group(str(path), mode="r+")
    target = root["target"][:]
    del root["target"]
    root.create_array("target", data=target[:, :1], chunks=(20, 1))
    assert any("target.shape must be (N, 2)" in p for p in validate_store(path)), validate_store(path)


def test_a_babbling_store_made_before_targets_were_recorded_is_valid(babble, tmp_path):
    assert validate_store(babble) == [] and "target" in zarr.open_group(str(babble), mode="r").array_keys()
    old = older_store(babble, tmp_path / "old.zarr")
    assert validate_store(old) == []
    gone = shutil.copytree(babble, tmp_path / "gone.zarr")          # a store that lists target but lost it: a defect
    shutil.rmtree(gone / "target")
    assert any("'target' must be present" in p for p in validate_store(gone))


def test_a_value_changed_after_writing_breaks_only_its_shards_checksum(copy):
    q = zarr.open_group(str(copy))["q"][33:34]
    rewrite(copy, "q", slice(33, 34), q * np.float32(0.5), as_written=False)  # still a plausible pose
    one_problem(copy, "checksum in its shard_done marker", "1 differ", "shards [2]", "rewrites the damaged shards")


def test_a_deleted_chunk_is_missing_not_zeros(copy):
    (copy / "image" / "c" / "1" / "0" / "0").unlink()  # reads back as 16 black images
    one_problem(copy, "image chunks must be on disk for every done shard", "1 missing", "shards [1]", "rewrites")


def test_a_store_without_checksums_cannot_be_proven_complete(copy):
    root = zarr.open_group(str(copy), mode="r+")
    del root["shard_done"]
    root.create_array("shard_done", data=np.ones(3, np.uint8), chunks=(1,))  # schema 1: a bare flag
    one_problem(copy, "shard_done must be a checksum per shard", "schema 1")


def test_missing_completion_marker(copy):
    zarr.open_group(str(copy), mode="r+").attrs["complete"] = False
    one_problem(copy, "store must be complete", "resume")


def test_a_shard_not_done(copy):
    zarr.open_group(str(copy), mode="r+")["shard_done"][1] = 0
    one_problem(copy, "every shard must be done", "[1]")


def test_corrupt_chunk_file(copy):
    chunk = copy / "image" / "c" / "1" / "0" / "0"
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped byte: the Zstd checksum must catch it
    chunk.write_bytes(bytes(data))
    one_problem(copy, "image rows 16:32 must be readable", "Zstd")


def test_truncated_chunk_file(copy):
    chunk = copy / "q" / "c" / "2" / "0"
    chunk.write_bytes(chunk.read_bytes()[:5])
    assert any("q rows 32:48 must be readable" in p for p in validate_store(copy))


def test_dropped_attr(copy):
    meta = copy / "zarr.json"
    doc = json.loads(meta.read_text())
    del doc["attributes"]["mjcf_sha256"]
    meta.write_text(json.dumps(doc))
    one_problem(copy, "root attrs", "mjcf_sha256")


def test_wrong_dtype(copy):
    root = zarr.open_group(str(copy), mode="r+")
    q = root["q"][:]
    del root["q"]
    root.create_array("q", data=q.astype(np.float64), chunks=(16, 2))
    one_problem(copy, "q.dtype must be float32", "float64")


def test_all_problems_are_reported_at_once(copy):
    root = zarr.open_group(str(copy), mode="r+")
    root["q"][0] = np.inf
    root.attrs["complete"] = False
    shutil.rmtree(copy / "jacobian")
    problems = validate_store(copy)
    assert len(problems) == 3 and sum("jacobian" in p for p in problems) == 1, problems


def test_not_a_store(tmp_path):
    (problem,) = validate_store(tmp_path)
    assert "must be a Zarr v3 dataset store" in problem


def test_summary_names_robot_arrays_and_validity(valid):
    text = summarize_store(valid)
    assert "planar2" in text and "uniform" in text and "(48, 64, 64)" in text and "valid" in text


def test_contact_sheet_draws_the_stored_pixel_on_the_marker(valid, tmp_path):
    png = write_contact_sheet(valid, tmp_path / "sheet.png", n=4)
    sheet = cv2.imread(str(png))
    assert sheet.shape == (2 * 192, 2 * 192, 3)  # 64 px tiles upscaled x3, a 2 x 2 grid
    red = (sheet[..., 2] > 200) & (sheet[..., 1] < 80) & (sheet[..., 0] < 80)
    assert red.sum() > 4 * 20  # a cross and circle in every tile
    root = zarr.open_group(str(valid), mode="r")
    u, v = root["ee_pixel"][0]
    assert root["image"][0][int(round(v)), int(round(u))] > 150  # the pixel sits on the bright marker


def test_contact_sheet_needs_images(tmp_path):
    path = generate(DatagenConfig(n=8, shard_size=8, images=False, out=tmp_path / "k.zarr"), progress=False)
    with pytest.raises(ValueError, match="store must be one with images"):
        write_contact_sheet(path, tmp_path / "x.png")
