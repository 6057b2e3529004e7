"""`bodyschema import` of robot-learning datasets: the HDF5 demo layout (data/demo_i/obs/<key>, episodes in natural
order, an ee key as ee_xyz) and a LeRobot v3.0 dataset that is not this project's own export (no units: --angles
and a body are needed; images as PNG in the parquet or as video decoded by OpenCV)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import zarr

from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.import_sources import planar2_frames, write_demo_hdf5

pytest.importorskip("h5py")
pytest.importorskip("pyarrow")


def test_hdf5_demo_episodes_in_natural_order_with_their_ee_readings(tmp_path):
    q, images = planar2_frames(24)
    ee = np.random.default_rng(1).normal(size=(24, 3))                 # a foreign frame: no reach check applies
    path = write_demo_hdf5(tmp_path / "demo.hdf5", q, images, episodes=12, ee=ee)   # demo_10 after demo_9
    store = import_recording(ImportConfig(source=path, out=tmp_path / "d.zarr", angles="rad", robot="planar2",
                                          joint_key=("joint_pos",), ee_key="eef_pos"))
    assert validate_store(store) == []
    root = zarr.open_group(str(store), mode="r")
    np.testing.assert_allclose(root["q"][:], q, atol=1e-6)
    np.testing.assert_array_equal(root["image"][:], images)
    np.testing.assert_array_equal(root["episode"][:], np.repeat(np.arange(12), 2))
    np.testing.assert_allclose(root["ee_xyz"][:], ee, atol=1e-6)
    assert root.attrs["reach_m"] is None and root.attrs["source"]["format"] == "hdf5"


def test_hdf5_demo_unknown_key_names_the_keys_there_are(tmp_path):
    q, images = planar2_frames(4)
    path = write_demo_hdf5(tmp_path / "demo.hdf5", q, images, episodes=2)
    with pytest.raises(ValueError, match="must be.*agentview_image.*joint_pos"):
        import_recording(ImportConfig(source=path, out=tmp_path / "d.zarr", angles="rad", robot="planar2",
                                      joint_key=("robot0_joint_pos",)))
    assert not (tmp_path / "d.zarr").exists()


@pytest.fixture(scope="module")
def foreign_lerobot(tmp_path_factory):
    """This project's LeRobot export of a babbling store, stripped of meta/bodyschema.json (units, body, attrs)."""
    from tests.datagen.export_stores import foreign_lerobot

    return foreign_lerobot(tmp_path_factory.mktemp("lerobot"))


def test_a_foreign_lerobot_dataset_needs_units_and_a_body(foreign_lerobot, tmp_path):
    store, source = foreign_lerobot
    with pytest.raises(ValueError, match="--angles must be"):
        import_recording(ImportConfig(source=source, out=tmp_path / "f.zarr", robot="planar2"))
    with pytest.raises(ValueError, match="the body must be"):
        import_recording(ImportConfig(source=source, out=tmp_path / "f.zarr", angles="rad"))
    back = import_recording(ImportConfig(source=source, out=tmp_path / "f.zarr", angles="rad", robot="planar2"))
    old, new = zarr.open_group(str(store), mode="r"), zarr.open_group(str(back), mode="r")
    for name in ("q", "image", "episode", "t"):
        np.testing.assert_array_equal(new[name][:], old[name][:], err_msg=name)
    assert "ee_xyz" not in new.array_keys()                             # only this project's export brings them


def test_lerobot_video_frames_are_decoded(foreign_lerobot, tmp_path):
    """The image feature re-encoded as one MPEG-4 video per episode: frames come back within codec loss."""
    import cv2
    import pandas as pd
    import pyarrow.parquet as pq

    store, source = foreign_lerobot
    video = shutil.copytree(source, tmp_path / "video")
    info = json.loads((video / "meta" / "info.json").read_text())
    key = next(k for k, f in info["features"].items() if f["dtype"] == "image")
    info["features"][key]["dtype"] = "video"
    info["video_path"] = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    (video / "meta" / "info.json").write_text(json.dumps(info))
    images = zarr.open_group(str(store), mode="r")["image"][:]         # (N, H, W, 3) RGB
    episodes_path = next((video / "meta" / "episodes").rglob("*.parquet"))
    episodes = pd.read_parquet(episodes_path)
    target = video / f"videos/{key}/chunk-000/file-000.mp4"
    target.parent.mkdir(parents=True)
    writer = cv2.VideoWriter(str(target), cv2.VideoWriter_fourcc(*"mp4v"), float(info["fps"]),
                             (images.shape[2], images.shape[1]))
    if not writer.isOpened():
        pytest.skip("OpenCV cannot write MPEG-4 here")
    for image in images:
        writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    writer.release()
    episodes[f"videos/{key}/chunk_index"] = 0
    episodes[f"videos/{key}/file_index"] = 0
    episodes[f"videos/{key}/from_timestamp"] = episodes["dataset_from_index"] / info["fps"]
    episodes.to_parquet(episodes_path, index=False)
    for path in (video / "data").rglob("*.parquet"):
        pq.write_table(pq.read_table(path).drop_columns([key]), path)
    back = import_recording(ImportConfig(source=video, out=tmp_path / "v.zarr", angles="rad", robot="planar2"))
    got = zarr.open_group(str(back), mode="r")["image"][:]
    assert got.shape == images.shape
    err = np.abs(got.astype(float) - images).mean()                    # intensity levels of 255: lossy codec
    assert err < 8.0 and err < np.abs(got[1:].astype(float) - images[:-1]).mean(), "each row its own frame"
