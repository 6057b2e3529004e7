"""`export_dataset(..., "lerobot")`: LeRobot's v3.0 layout, checked against the format's schema with pyarrow, and
every frame read back equals the store's (images decoded from their PNG bytes). Every column must have the arrow
type LeRobot's reader casts it to (`get_hf_features_from_features`: shape (1,) → a scalar Value, shape (k,) → a
k-list, image → Image), so a 1-wide feature (panda's touch) loads; `action` is a babbling store's servo targets, and
the next frame's state for a store without them (independent poses, a babbling store made before datagen recorded
its targets). Where `lerobot` is installed (not a dependency: its releases pin other torch versions), its own
`LeRobotDataset` loads the export of every shipped robot."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import zarr

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.exchange import export_lerobot
from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.generate import generate
from tests.datagen.export_stores import babble_store, older_store, uniform_store

pq = pytest.importorskip("pyarrow.parquet")


INFO_KEYS = {"codebase_version", "robot_type", "total_episodes", "total_frames", "total_tasks", "chunks_size",
             "data_files_size_in_mb", "video_files_size_in_mb", "fps", "splits", "data_path", "video_path", "features"}
INDEX_COLUMNS = {"timestamp", "frame_index", "episode_index", "index", "task_index"}
EPISODE_COLUMNS = {"episode_index", "tasks", "length", "data/chunk_index", "data/file_index", "dataset_from_index",
                   "dataset_to_index", "meta/episodes/chunk_index", "meta/episodes/file_index"}
ROBOTS = ("planar2", "nao_arm", "panda")                     # the shipped robots; panda has a touch sensor


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
    assert_columns_as_lerobot_reads_them(info, frames)
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
    assert all(set(s) == {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}
               for s in stats.values())                         # LeRobot's keys (test_export_lerobot_stats.py)


def lerobot_arrow_type(feat: dict):
    """The arrow type LeRobot's reader casts a column of this feature to (its `get_hf_features_from_features`)."""
    import pyarrow as pa

    if feat["dtype"] == "image":
        return pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    value = pa.from_numpy_dtype(np.dtype(feat["dtype"]))
    return value if feat["shape"] == [1] else pa.list_(value, feat["shape"][0])


def lerobot_hf_feature(feat: dict) -> dict:
    """The `datasets` feature LeRobot builds from an info.json feature, as `datasets` serialises it."""
    if feat["dtype"] == "image":
        return {"_type": "Image"}
    value = {"dtype": feat["dtype"], "_type": "Value"}
    return value if feat["shape"] == [1] else {"feature": value, "length": feat["shape"][0], "_type": "Sequence"}


def assert_columns_as_lerobot_reads_them(info: dict, frames: list) -> None:
    """Every feature is a column of every data file, of the type LeRobot casts it to (so the cast that failed for
    1-wide features, a one-element list to a scalar, is not needed), and the files' `datasets` metadata says so."""
    import pyarrow as pa

    feats = info["features"]
    want = pa.schema([(key, lerobot_arrow_type(feat)) for key, feat in feats.items()])
    for table in frames:
        assert set(table.column_names) == set(feats)
        for key in feats:
            assert table.schema.field(key).type == want.field(key).type, key
        hf = json.loads(table.schema.metadata[b"huggingface"])["info"]["features"]
        assert hf == {key: lerobot_hf_feature(feat) for key, feat in feats.items()}
        table.select(want.names).cast(want)                     # what LeRobot's reader does, here without `datasets`


def actions(frames: list) -> tuple[np.ndarray, np.ndarray]:
    """(action (N, Dq), episode_index (N,)) of the exported frames, in row order."""
    table = {k: np.concatenate([t[k].to_numpy(zero_copy_only=False) for t in frames]) for k in ("index", "action",
                                                                                                "episode_index")}
    order = np.argsort(table["index"])
    return np.stack(table["action"][order]), table["episode_index"][order]


def assert_action_is_the_command(info: dict, frames: list, out, root: zarr.Group) -> None:
    """`action` = the store's servo targets where it has them, else the next frame's state; meta says which."""
    ours = json.loads((out / "meta" / "bodyschema.json").read_text())
    assert info["features"]["action"] == info["features"]["observation.state"] and ours["units"]["action"] == "rad"
    if "target" in root.array_keys():
        np.testing.assert_array_equal(actions(frames)[0], root["target"][:])
        assert ours["arrays"]["action"] == "target" and "servo targets" in ours["action"]
    else:
        assert_action_is_the_next_state(info, frames, root["q"][:])
        assert "action" not in ours["arrays"] and "next frame" in ours["action"]


def assert_action_is_the_next_state(info: dict, frames: list, q: np.ndarray) -> None:
    """`action` = the next frame's state in the same episode; an episode's last frame holds its own."""
    action, episode = actions(frames)                                                       # (N, Dq), (N,)
    last = np.r_[episode[1:] != episode[:-1], True]                                         # an episode's last row
    np.testing.assert_array_equal(action[~last], q[1:][~last[:-1]])
    np.testing.assert_array_equal(action[last], q[last])


def test_frames_equal_the_store(stores, tmp_path, monkeypatch):
    monkeypatch.setattr(export_lerobot, "DATA_FILE_MB", 0.05)      # ~13 frames of 24×32 RGB per file: several files
    monkeypatch.setattr("bodyschema.datagen.store.rows.ROWS_PER_READ", 16)   # several row groups per file
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
    assert "target" in root.array_keys()
    assert_action_is_the_command(info, frames, out, root)                          # the servo targets
    ours = json.loads((out / "meta" / "bodyschema.json").read_text())
    assert ours["units"]["observation.state"] == "rad" and ours["body"]["robot"] == root.attrs["robot"]


def test_a_store_older_store_exports_the_next_state_as_action(stores, tmp_path):
    old = older_store(stores["babble"], tmp_path / "old.zarr")           # as datagen wrote it before targets
    out = export_dataset(old, tmp_path / "lr", "lerobot")
    info, _, _, frames = _read(out)
    root = zarr.open_group(str(old), mode="r")
    assert "target" not in root.array_keys() and info["total_episodes"] > 1
    assert_columns_as_lerobot_reads_them(info, frames)
    assert_action_is_the_command(info, frames, out, root)                          # the next frame's state


def test_independent_poses_are_one_episode_at_one_frame_per_second(stores, tmp_path):
    out = export_dataset(stores["uniform"], tmp_path / "lr", "lerobot")
    info, episodes, _, frames = _read(out)
    assert info["fps"] == 1 and info["total_episodes"] == 1 == len(episodes)
    np.testing.assert_array_equal(frames[0]["timestamp"].to_numpy(), np.arange(40, dtype=np.float32))


@pytest.fixture(scope="module", params=[(robot, sampler) for robot in ROBOTS for sampler in ("babble", "uniform")],
                ids=lambda p: "-".join(p))
def robot_export(request, tmp_path_factory):
    """(store, export) of a tiny store of each shipped robot: babbling with RGB images, or uniform poses."""
    robot, sampler = request.param
    folder = tmp_path_factory.mktemp(f"{robot}_{sampler}")
    babble = {"sampler": "babble", "episode_s": 1.0, "record_hz": 10.0, "image_size": (24, 32), "rgb": True}
    config = DatagenConfig(robot=robot, n=30, out=folder / "s.zarr",
                           **(babble if sampler == "babble" else {"images": False}))
    store = generate(config)
    return store, export_dataset(store, folder / "lr", "lerobot")


def test_every_robot_export_has_the_schema_lerobot_reads(robot_export):
    store, out = robot_export
    info, _, _, frames = _read(out)
    root = zarr.open_group(str(store), mode="r")
    assert_columns_as_lerobot_reads_them(info, frames)
    assert_action_is_the_command(info, frames, out, root)
    assert ("target" in root.array_keys()) == (root.attrs["sampler"] == "babble")
    assert info["features"]["action"]["names"] == root.attrs["joint_names"]
    if "touch" in root.array_keys():                                   # panda: the 1-wide feature, a scalar column
        assert info["features"]["observation.touch"]["shape"] == [1]
        touch = np.concatenate([t["observation.touch"].to_numpy() for t in frames])
        index = np.concatenate([t["index"].to_numpy() for t in frames])
        np.testing.assert_array_equal(touch[np.argsort(index)], root["touch"][:, 0])
    assert ("touch" in root.array_keys()) == (root.attrs["robot"] == "panda")


def test_every_robot_export_loads_with_lerobot(robot_export):
    lerobot = pytest.importorskip("lerobot.datasets.lerobot_dataset", reason="lerobot is not a dependency")
    torch = pytest.importorskip("torch")
    store, out = robot_export
    root = zarr.open_group(str(store), mode="r")
    dataset = lerobot.LeRobotDataset("local/export", root=out)
    n = root["q"].shape[0]
    assert len(dataset) == n
    batches = list(torch.utils.data.DataLoader(dataset, batch_size=8))
    state = torch.cat([b["observation.state"] for b in batches]).numpy()
    np.testing.assert_array_equal(state, root["q"][:])
    action = torch.cat([b["action"] for b in batches]).numpy()
    if "target" in root.array_keys():
        np.testing.assert_array_equal(action, root["target"][:])
    else:
        np.testing.assert_array_equal(action[:-1][root_not_last(root)], root["q"][1:][root_not_last(root)])
    if "touch" in root.array_keys():
        np.testing.assert_array_equal(torch.cat([b["observation.touch"] for b in batches]).numpy(), root["touch"][:, 0])


def root_not_last(root: zarr.Group) -> np.ndarray:
    """(N - 1,) True where row i is not its episode's last (so row i + 1 is its next frame)."""
    n = root["q"].shape[0]
    if "episode" not in root.array_keys():
        return np.ones(n - 1, bool)
    episode = root["episode"][:]
    return episode[1:] == episode[:-1]
