"""`validate_store` catches each kind of damage (one test per kind) and reports all of them at once."""

import json
import shutil

import cv2
import numpy as np
import pytest
import zarr

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.contact_sheet import write_contact_sheet
from bodyschema.datagen.generate import generate
from bodyschema.datagen.camera import project
from bodyschema.datagen.validate import summarize_store, validate_store


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    out = tmp_path_factory.mktemp("valid") / "planar2.zarr"
    return generate(DatagenConfig(robot="planar2", n=48, shard_size=16, seed=3, out=out), progress=False)


@pytest.fixture
def copy(valid, tmp_path):
    return shutil.copytree(valid, tmp_path / "copy.zarr")


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
    zarr.open_group(str(copy), mode="r+")["q"][5] = np.nan
    one_problem(copy, "q must be finite", "first at row 5")


def test_q_outside_the_recorded_ranges(copy):
    root = zarr.open_group(str(copy), mode="r+")
    q = root["q"][:]
    q[7, 0] = root.attrs["sampling_ranges"][0][1] + 0.01
    root["q"][:] = q
    one_problem(copy, "q must be inside the recorded sampling_ranges", "first at row 7")


def test_ee_pixel_shifted_from_the_projection(copy):
    root = zarr.open_group(str(copy), mode="r+")
    root["ee_pixel"][10:12] = root["ee_pixel"][10:12] + np.float32(0.5)
    one_problem(copy, "ee_pixel must be ee_xyz projected", "2 rows", "first at row 10")


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
