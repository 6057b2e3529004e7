"""`export_dataset(..., "lerobot")`: LeRobot's v3.0 layout, checked against the format's schema with pyarrow (the
`lerobot` package cannot be installed beside our torch pin: 0.4.x requires torch < 2.11), and every frame read back
equals the store's (images decoded from their PNG bytes)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import zarr

from bodyschema.datagen import export_lerobot
from bodyschema.datagen.export import export_dataset
from tests.datagen.export_stores import babble_store, uniform_store

pq = pytest.importorskip("pyarrow.parquet")


INFO_KEYS = {"codebase_version", "robot_type", "total_episodes", "total_frames", "total_tasks", "chunks_size",
             "data_files_size_in_mb", "video_files_size_in_mb", "fps", "splits", "data_path", "video_path", "features"}
INDEX_COLUMNS = {"timestamp", "frame_index", "episode_index", "index", "task_index"}
EPISODE_COLUMNS = {"episode_index", "tasks", "length", "data/chunk_index", "data/file_index", "dataset_from_index",
                   "dataset_to_index", "meta/episodes/chunk_index", "meta/episodes/file_index"}
ARROW_TYPES = {"float32": "float", "int64": "int64"}


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stores")
    return {"babble": babble_store(folder), "uniform": uniform_store(folder)}


def _read(out):
    info = json.loads((out / "meta" / "info.json").read_text())
    episodes = pq.read_table(out / export_lerobot.EPISODES_PATH).to_pylist()
    files = sorted((out / "data").glob("chunk-*/file-*.parquet"))
    frames = [pq.read_table(f) for f in files]
    return info, episodes, files, frames


@pytest.mark.parametrize("which", ["babble", "uniform"])
def test_the_layout_follows_lerobot_v3(stores, which, tmp_path):
    out = export_dataset(stores[which], tmp_path / "lr", "lerobot")
    info, episodes, files, frames = _read(out)
    assert INFO_KEYS <= set(info) and info["codebase_version"] == "v3.0"
    assert isinstance(info["fps"], int) and info["fps"] >= 1
    assert INDEX_COLUMNS <= set(info["features"])
    for key, feat in info["features"].items():
        assert set(feat) == {"dtype", "shape", "names"} and "/" not in key, key
        if feat["dtype"] == "image":
            assert feat["names"] == ["height", "width", "channels"] and len(feat["shape"]) == 3, key
        elif key in INDEX_COLUMNS:
            assert feat["shape"] == [1] and feat["names"] is None, key
        else:                                   # one name per value: the joint order, x/y/z, u/v ...
            assert len(feat["shape"]) == 1 and len(feat["names"]) == feat["shape"][0], key
    # every feature is a column of every data file, with its declared dtype and shape; nothing else is
    for table in frames:
        assert set(table.column_names) == set(info["features"])
        for key, feat in info["features"].items():
            column = table.schema.field(key).type
            if feat["dtype"] == "image":
                assert str(column) == "struct<bytes: binary, path: string>", key
            elif key in INDEX_COLUMNS:
                assert str(column) == ARROW_TYPES[feat["dtype"]], key
            else:
                assert column.list_size == feat["shape"][0] and str(column.value_type) == ARROW_TYPES[feat["dtype"]]
    # the paths come from data_path, and the episode table points at the rows it owns
    assert {str(f.relative_to(out)) for f in files} == {
        info["data_path"].format(chunk_index=e["data/chunk_index"], file_index=e["data/file_index"]) for e in episodes}
    assert set(episodes[0]) == EPISODE_COLUMNS
    assert [e["episode_index"] for e in episodes] == list(range(info["total_episodes"]))
    assert sum(e["length"] for e in episodes) == info["total_frames"] == sum(t.num_rows for t in frames)
    index = np.concatenate([t["index"].to_numpy() for t in frames])
    episode = np.concatenate([t["episode_index"].to_numpy() for t in frames])
    for e in episodes:
        rows = index[episode == e["episode_index"]]
        assert rows.tolist() == list(range(e["dataset_from_index"], e["dataset_to_index"]))
    tasks = pq.read_table(out / "meta" / "tasks.parquet").to_pandas()
    assert tasks["task_index"].tolist() == [0] and episodes[0]["tasks"] == [tasks.index[0]]
    stats = json.loads((out / "meta" / "stats.json").read_text())
    assert set(stats) == set(info["features"])
    assert all(set(s) == {"min", "max", "mean", "std", "count"} for s in stats.values())


def test_frames_equal_the_store(stores, tmp_path, monkeypatch):
    monkeypatch.setattr(export_lerobot, "DATA_FILE_MB", 0.05)      # ~13 frames of 24×32 RGB per file: several files
    monkeypatch.setattr("bodyschema.datagen.export.ROWS_PER_READ", 16)   # several row groups per file
    store = stores["babble"]
    out = export_dataset(store, tmp_path / "lr", "lerobot")
    info, episodes, files, frames = _read(out)
    root = zarr.open_group(str(store), mode="r")
    assert len(files) > 1 and info["total_episodes"] == len(np.unique(root["episode"][:])) > 1
    table = {k: np.concatenate([t[k].to_numpy(zero_copy_only=False) for t in frames]) for k in frames[0].column_names}
    order = np.argsort(table["index"])
    np.testing.assert_array_equal(np.stack(table["observation.state"][order]), root["q"][:])
    np.testing.assert_array_equal(np.stack(table["observation.ee_pixel"][order]), root["ee_pixel"][:])
    np.testing.assert_array_equal(np.stack(table["observation.jacobian"][order]).reshape(root["jacobian"].shape),
                                  root["jacobian"][:])
    np.testing.assert_array_equal(table["timestamp"][order], root["t"][:])
    images = np.stack([cv2.cvtColor(cv2.imdecode(np.frombuffer(cell["bytes"], np.uint8), cv2.IMREAD_COLOR),
                                    cv2.COLOR_BGR2RGB) for cell in table[export_lerobot.image_key(root)][order]])
    np.testing.assert_array_equal(images, root["image"][:])                     # PNG: lossless
    assert info["features"]["observation.state"]["names"] == root.attrs["joint_names"]
    assert info["fps"] == root.attrs["sampler_params"]["record_hz"]
    ours = json.loads((out / "meta" / "bodyschema.json").read_text())
    assert ours["units"]["observation.state"] == "rad" and ours["body"]["robot"] == root.attrs["robot"]


def test_independent_poses_are_one_episode_at_one_frame_per_second(stores, tmp_path):
    out = export_dataset(stores["uniform"], tmp_path / "lr", "lerobot")
    info, episodes, _, frames = _read(out)
    assert info["fps"] == 1 and info["total_episodes"] == 1 == len(episodes)
    np.testing.assert_array_equal(frames[0]["timestamp"].to_numpy(), np.arange(40, dtype=np.float32))


def test_loads_with_lerobot_where_it_installs(stores, tmp_path):
    lerobot = pytest.importorskip("lerobot.datasets.lerobot_dataset", reason="lerobot 0.4.x pins torch < 2.11")
    out = export_dataset(stores["babble"], tmp_path / "lr", "lerobot")
    dataset = lerobot.LeRobotDataset("local/babble", root=out)
    root = zarr.open_group(str(stores["babble"]), mode="r")
    assert len(dataset) == root["q"].shape[0]
    np.testing.assert_allclose(dataset[5]["observation.state"].numpy(), root["q"][5])
