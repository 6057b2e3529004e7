"""The Zarr store: schema, chunk-aligned shard writes, markers, and NaN for rows never written."""

import numpy as np
import pytest

from bodyschema.datagen.store.schema import (
    DONE,
    create_store,
    features,
    is_complete,
    mark_complete,
    mark_shard_done,
    open_store,
    shards_done,
    write_shard,
)


def test_features_follow_the_schema():
    f = features(4, (56, 80), sensors=("touch",), babble=True)
    assert f["q"]["shape"] == [4] and f["jacobian"]["shape"] == [3, 4] and f["image"]["shape"] == [56, 80]
    floats = ("q", "ee_xyz", "ee_rot", "ee_pixel", "jacobian", "touch", "qvel", "t")
    assert {f[k]["dtype"] for k in floats} == {"float32"}
    assert f["image"]["dtype"] == "uint8" and f["episode"]["dtype"] == "int32"
    assert f["q"]["unit"] == "rad" and f["ee_xyz"]["unit"] == "m" and f["ee_pixel"]["unit"] == "px"
    assert f["target"] == {"dtype": "float32", "shape": [4], "unit": "rad", "names": ["joint"]}   # babbling commands
    kinematic = features(2, None, sensors=(), babble=False)
    assert set(kinematic) == {"q", "ee_xyz", "ee_rot", "ee_pixel", "jacobian"}
    assert features(2, (8, 8, 3), (), False)["image"]["names"] == ["row", "col", "channel"]


def test_features_pin_the_store_format_key_order_included():
    """The shipped format, as a literal: features come from the modality table, and its order is the store's."""
    f = features(4, (56, 80), sensors=("touch",), babble=True)

    def vec(shape, unit, names):
        return {"dtype": "float32", "shape": shape, "unit": unit, "names": names}

    assert list(f.items()) == list({
        "q": vec([4], "rad", ["joint"]), "ee_xyz": vec([3], "m", ["x", "y", "z"]),
        "ee_rot": vec([9], "", ["r00", "r01", "r02", "r10", "r11", "r12", "r20", "r21", "r22"]),
        "ee_pixel": vec([2], "px", ["u", "v"]),
        "jacobian": vec([3, 4], "m/rad", ["xyz", "joint"]),
        "image": {"dtype": "uint8", "shape": [56, 80], "unit": "intensity", "names": ["row", "col"]},
        "touch": vec([1], "N", ["contact"]), "qvel": vec([4], "rad/s", ["joint"]),
        "episode": {"dtype": "int32", "shape": [], "unit": "index", "names": []}, "t": vec([], "s", []),
        "target": vec([4], "rad", ["joint"])}.items())
    assert list(features(2, None, (), False)) == ["q", "ee_xyz", "ee_rot", "ee_pixel", "jacobian"]


@pytest.fixture
def store(tmp_path):
    feats = features(2, (8, 8), sensors=(), babble=False)
    root = create_store(tmp_path / "s.zarr", feats, n=10, chunk_len=4, n_shards=3, attrs={"robot": "planar2"})
    return tmp_path / "s.zarr", root


def test_created_store_has_chunk_aligned_arrays_and_no_marker(store):
    path, root = store
    assert root["q"].shape == (10, 2) and root["q"].chunks == (4, 2)
    assert root["image"].shape == (10, 8, 8) and root["image"].chunks == (4, 8, 8)
    assert root[DONE].shape == (3,) and not shards_done(root).any()
    assert root.attrs["robot"] == "planar2" and root.attrs["created"] is True
    assert not is_complete(path)
    assert np.isnan(root["q"][:]).all()  # never-written rows are visibly missing


def test_a_shard_writes_only_its_own_chunk_files(store):
    path, root = store
    rows = {"q": np.ones((4, 2), np.float32), "image": np.full((4, 8, 8), 7, np.uint8)}
    write_shard(root, 4, rows)
    mark_shard_done(root, 1, digest=12345)
    assert sorted(p.name for p in (path / "q" / "c").iterdir()) == ["1"]
    assert sorted(p.name for p in (path / DONE / "c").iterdir()) == ["1"]
    again = open_store(path)
    assert np.array_equal(again["q"][4:8], rows["q"]) and np.isnan(again["q"][:4]).all()
    assert np.array_equal(shards_done(again), [False, True, False])


def test_the_completion_marker_is_explicit(store):
    path, root = store
    mark_complete(root)
    assert is_complete(path) and "completed_at" in open_store(path).attrs


def test_opening_a_non_store_names_the_fix(tmp_path):
    with pytest.raises(FileNotFoundError, match="path must be a Zarr v3 dataset store.*bodyschema datagen"):
        open_store(tmp_path)
    assert not is_complete(tmp_path / "missing.zarr")
