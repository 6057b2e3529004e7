"""Training data: bad stores are refused, splits are disjoint and seeded, the digest follows the content."""

import shutil

import numpy as np
import pytest
import torch
import zarr

from bodyschema.training.data import as_float, load_dataset, split_rows


def test_loads_kinematic_store_with_seeded_random_split(kin_store):
    a = load_dataset(kin_store, "ee_xyz", val_fraction=0.25, seed=3)
    b = load_dataset(kin_store, "ee_xyz", val_fraction=0.25, seed=3)
    root = zarr.open_group(str(kin_store), mode="r")
    assert a.split_by == "random" and len(a.val) == 100 and len(a.train) == 300
    assert set(a.train.rows).isdisjoint(a.val.rows) and len(set(a.train.rows) | set(a.val.rows)) == 400
    np.testing.assert_array_equal(a.val.rows, b.val.rows)
    np.testing.assert_array_equal(a.train.x, np.asarray(root["ee_xyz"][:])[a.train.rows])
    assert a.train.q.dtype == np.float32 and a.output_shape("ee_xyz") == (3,)
    assert a.body.robot == "planar2" and a.body.q_low == (-2.5, -2.5) and a.sha256 == b.sha256
    c = load_dataset(kin_store, "ee_xyz", val_fraction=0.25, seed=4)
    assert not np.array_equal(a.val.rows, c.val.rows), "another seed must give another split"


def test_babbling_store_holds_out_whole_episodes_and_keeps_images_uint8(image_store):
    data = load_dataset(image_store, "image", val_fraction=0.25, seed=0)
    episode = np.asarray(zarr.open_group(str(image_store), mode="r")["episode"][:])
    assert data.split_by == "episode"
    assert set(episode[data.train.rows]).isdisjoint(episode[data.val.rows])
    assert 0.15 <= len(data.val) / len(episode) <= 0.45
    assert data.is_image("image") and data.train.x.dtype == np.uint8 and data.output_shape("image") == (16, 16)
    batch = as_float(data.train.x[:4])
    assert batch.dtype == torch.float32 and 0 <= batch.min() and batch.max() <= 1
    torch.testing.assert_close(batch * 255, torch.as_tensor(data.train.x[:4]).float())


def test_split_rows_never_leaves_a_side_empty():
    rng = np.random.default_rng(0)
    train, val, how = split_rows(np.array([0, 0, 0, 1]), 4, 0.99, rng)      # 99 % asked, one episode kept
    assert how == "episode" and list(train) and list(val)
    train, val, how = split_rows(np.zeros(5, dtype=int), 5, 0.01, rng)       # one episode: random rows
    assert how == "random" and len(val) == 1 and len(train) == 4


def test_digest_changes_with_content_and_max_train_caps(kin_store, tmp_path):
    copy = shutil.copytree(kin_store, tmp_path / "copy.zarr")
    base = load_dataset(copy, "ee_xyz", max_train=50)
    assert len(base.train) == 50
    root = zarr.open_group(str(copy), mode="r+")
    root["q"][7] = root["q"][7] * np.float32(0.999)       # q in range, pixels consistent
    from bodyschema.datagen.store.integrity import shard_digest
    from bodyschema.datagen.store.schema import mark_shard_done

    mark_shard_done(root, 0, shard_digest(root, 0, 100))   # re-recorded as datagen would: still a valid store
    changed = load_dataset(copy, "ee_xyz", max_train=50)
    assert changed.sha256 != base.sha256


def test_the_digest_is_the_stores_whichever_modality_is_read(image_store, kin_store):
    """One store, one dataset digest in MLflow: reading ee_xyz, image or both from it gives the same sha256."""
    digests = {load_dataset(image_store, m).sha256 for m in ("ee_xyz", "image", "ee_pixel,image")}
    assert len(digests) == 1 and digests != {load_dataset(kin_store, "ee_xyz").sha256}


def test_incomplete_store_is_refused_with_every_problem(kin_store, tmp_path):
    copy = shutil.copytree(kin_store, tmp_path / "copy.zarr")
    zarr.open_group(str(copy), mode="r+").attrs["complete"] = False
    with pytest.raises(ValueError, match="cannot be used for training") as info:
        load_dataset(copy, "image")
    message = str(info.value)
    assert "complete" in message and "bodyschema datagen" in message
    assert "data array 'image' must be present" in message and "ee_xyz" in message   # names the arrays there


def test_missing_store_names_the_fix(tmp_path):
    with pytest.raises(ValueError, match="Zarr v3 dataset store"):
        load_dataset(tmp_path / "nowhere.zarr", "ee_xyz")


def test_several_modalities_share_rows_and_split(image_store):
    data = load_dataset(image_store, "ee_xyz,image", seed=1)
    assert data.modalities == ("ee_xyz", "image") and set(data.val.xs) == {"ee_xyz", "image"}
    root = zarr.open_group(str(image_store), mode="r")
    np.testing.assert_array_equal(data.val.xs["image"], np.asarray(root["image"][:])[data.val.rows])
    np.testing.assert_array_equal(data.val.xs["ee_xyz"], np.asarray(root["ee_xyz"][:])[data.val.rows])
    with pytest.raises(ValueError, match="exactly one"):
        _ = data.train.x   # one modality's x is ambiguous with two
