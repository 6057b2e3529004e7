"""`bodyschema import` of LeRobot v3.0 video features in the codecs LeRobot writes: AV1 (libsvtav1, its default),
h264 and hevc, encoded here with PyAV as LeRobot's encoder does (yuv420p, GOP 2, CRF 30), all episodes in one file.
PyAV decodes every one; OpenCV's wheel (the fallback without PyAV) decodes h264 but no AV1, which is the house error
naming PyAV."""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pytest
import zarr

from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording

av = pytest.importorskip("av")
pytest.importorskip("pyarrow")

CODECS = {"av1": "libsvtav1", "h264": "libx264", "hevc": "libx265"}   # LeRobot's vcodec choices
# The codec's tolerance, in intensity levels of 255, CRF 30 on 24×32 RGB planar2 renders: the mean absolute error of
# the worst frame (measured 4.0 AV1, 2.8 h264, 3.4 hevc) and the 99th percentile of every pixel's (15, 19, 21). Single
# pixels go further (up to 240): yuv420p keeps one colour per 2×2 block, and the arm's coloured edges are 1-2 px.
MEAN_TOL, P99_TOL = 6.0, 32
CODE_ROWS = 6


@pytest.fixture(scope="module")
def lerobot_with_images(tmp_path_factory):
    """This project's LeRobot export of a babbling store (4 episodes, RGB), stripped of meta/bodyschema.json."""
    from tests.datagen.export_stores import foreign_lerobot

    folder = tmp_path_factory.mktemp("video")
    store, out = foreign_lerobot(folder)
    images = zarr.open_group(str(store), mode="r")["image"][:]             # (N, H, W, 3) RGB uint8
    return with_frame_number(images), out


def with_frame_number(images: np.ndarray) -> np.ndarray:
    """The renders with frame i's number in binary across the top CODE_ROWS rows (8 stripes, white = 1): at 20 Hz
    neighbouring renders differ by ~1 level, less than the codec's error, so only a code tells frames apart."""
    n, h, w, _ = images.shape
    bits = (np.arange(n)[:, None] >> np.arange(8)[::-1]) & 1                    # (N, 8)
    out = images.copy()
    out[:, :CODE_ROWS] = 255 * np.repeat(bits, w // 8, axis=1)[:, None, :, None].astype(np.uint8)
    return out


def as_video(source, images: np.ndarray, encoder: str, folder):
    """A copy of `source` whose image feature is a video feature, its frames encoded by `encoder` in one file."""
    import pandas as pd
    import pyarrow.parquet as pq

    if encoder not in av.codecs_available:
        pytest.skip(f"this PyAV wheel has no {encoder} encoder")
    video = shutil.copytree(source, folder)
    info = json.loads((video / "meta" / "info.json").read_text())
    key = next(k for k, f in info["features"].items() if f["dtype"] == "image")
    info["features"][key]["dtype"] = "video"
    info["video_path"] = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    (video / "meta" / "info.json").write_text(json.dumps(info))
    path = video / f"videos/{key}/chunk-000/file-000.mp4"
    path.parent.mkdir(parents=True)
    with av.open(str(path), "w") as container:
        stream = container.add_stream(encoder, rate=info["fps"], options={"g": "2", "crf": "30"})
        stream.width, stream.height, stream.pix_fmt = images.shape[2], images.shape[1], "yuv420p"
        for image in images:
            container.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        container.mux(stream.encode())
    episodes_path = next((video / "meta" / "episodes").rglob("*.parquet"))
    episodes = pd.read_parquet(episodes_path)
    episodes[f"videos/{key}/chunk_index"] = 0
    episodes[f"videos/{key}/file_index"] = 0
    episodes[f"videos/{key}/from_timestamp"] = episodes["dataset_from_index"] / info["fps"]
    episodes.to_parquet(episodes_path, index=False)
    for data in (video / "data").rglob("*.parquet"):
        pq.write_table(pq.read_table(data).drop_columns([key]), data)
    return video


@pytest.mark.parametrize("codec", CODECS)
def test_every_codec_lerobot_writes_imports_frame_for_frame(codec, lerobot_with_images, tmp_path):
    images, source = lerobot_with_images
    video = as_video(source, images, CODECS[codec], tmp_path / "video")
    back = import_recording(ImportConfig(source=video, out=tmp_path / "v.zarr", angles="rad", robot="planar2"))
    got = zarr.open_group(str(back), mode="r")["image"][:].astype(float)
    assert got.shape == images.shape
    err = np.abs(got - images).mean(axis=(1, 2, 3))                              # (N,) per frame
    assert err.max() < MEAN_TOL, f"{codec}: worst frame off by {err.max():.2f} levels on average"
    assert np.percentile(np.abs(got - images), 99) <= P99_TOL
    code = np.abs(got[:, None, :CODE_ROWS] - images[None, :, :CODE_ROWS]).mean(axis=(2, 3, 4))   # (N, N)
    np.testing.assert_array_equal(code.argmin(axis=1), np.arange(len(images)), "each row its own frame")


def test_without_pyav_opencv_decodes_h264_and_refuses_av1_naming_pyav(lerobot_with_images, tmp_path, monkeypatch):
    images, source = lerobot_with_images
    h264 = as_video(source, images, CODECS["h264"], tmp_path / "h264")
    av1 = as_video(source, images, CODECS["av1"], tmp_path / "av1")
    monkeypatch.setitem(sys.modules, "av", None)                     # `import av` raises ImportError
    back = import_recording(ImportConfig(source=h264, out=tmp_path / "h.zarr", angles="rad", robot="planar2"))
    got = zarr.open_group(str(back), mode="r")["image"][:].astype(float)
    assert np.abs(got - images).mean(axis=(1, 2, 3)).max() < MEAN_TOL
    import cv2
    capture = cv2.VideoCapture(str(next(av1.rglob("*.mp4"))), cv2.CAP_FFMPEG)
    if capture.isOpened() and capture.read()[0]:
        pytest.skip("this OpenCV decodes AV1 itself")
    capture.release()
    with pytest.raises(ValueError, match="(?s)video file-000.mp4 must be decodable by .*PyAV is not installed.*"
                                         "pip install av"):
        import_recording(ImportConfig(source=av1, out=tmp_path / "a.zarr", angles="rad", robot="planar2"))
    assert not (tmp_path / "a.zarr").exists()


def test_a_file_pyav_cannot_decode_is_the_house_error(lerobot_with_images, tmp_path):
    images, source = lerobot_with_images
    video = as_video(source, images, CODECS["h264"], tmp_path / "video")
    path = next(video.rglob("*.mp4"))
    path.write_bytes(b"not a video" * 100)
    with pytest.raises(ValueError, match="video file-000.mp4 must be decodable by PyAV"):
        import_recording(ImportConfig(source=video, out=tmp_path / "v.zarr", angles="rad", robot="planar2"))
    assert not (tmp_path / "v.zarr").exists()
