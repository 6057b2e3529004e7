"""LeRobot v3.0 video features: the frame of each row, decoded with PyAV where it is installed (the `export` extra;
LeRobot decodes with it too), else with OpenCV's FFmpeg backend.

An episode's frames sit in one video file (meta/episodes: `videos/<key>/chunk_index`, `file_index`,
`from_timestamp`); the row's frame is number round((from_timestamp + timestamp) · fps) of that file. Each file is
decoded once, front to back (seeking in long-GOP codecs is not frame-exact). The codecs LeRobot writes (AV1 through
libsvtav1, its default; h264; hevc) all decode with PyAV's wheel (av 18: dav1d for AV1), while OpenCV's wheel has no
AV1 decoder. A codec the decoder cannot read is the house error, not an empty image.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bodyschema.datagen.exchange.importers.folder_csv import from_opencv
from bodyschema.errors import must_be

VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"   # LeRobot's default
HINT = ("Install PyAV (`pip install av`, in the export extra), which decodes every codec LeRobot writes (AV1 by "
        "default, h264, hevc); or re-encode the dataset with image (PNG) features.")


def video_frames(root: Path, info: dict, frames, key: str) -> list[np.ndarray]:
    import pandas as pd

    where = root / "meta" / "episodes"
    files = sorted(where.glob("chunk-*/*.parquet"))
    if not files:
        raise ValueError(must_be(f"{where}", "LeRobot's episode table (chunk-*/*.parquet)", "no parquet file",
                                 "A video feature needs it to find each episode's file."))
    episodes = pd.concat([pd.read_parquet(p) for p in files])
    needed = ["episode_index", *(f"videos/{key}/{c}" for c in ("chunk_index", "file_index", "from_timestamp"))]
    missing = [c for c in needed if c not in episodes.columns]
    if missing:
        raise ValueError(must_be(f"the columns {missing} of the episode table {where}",
                                 f"present (the video feature {key!r} needs {needed})", "absent", HINT))
    episodes = episodes.set_index("episode_index")
    fps = info.get("fps")
    if not isinstance(fps, (int, float)) or not fps > 0:
        raise ValueError(must_be(f"fps in {root / 'meta' / 'info.json'}", "a frame rate > 0 (Hz)", fps))
    fps = float(fps)
    template = info.get("video_path") or VIDEO_PATH
    absent = [c for c in ("episode_index", "timestamp") if c not in frames.column_names]
    if absent:
        raise ValueError(must_be(f"the columns {absent} of the frames in {root / 'data'}",
                                 "present (a video feature needs them)", "absent"))
    decoded: dict[Path, list[np.ndarray]] = {}
    out = []
    for episode, t in zip(frames.column("episode_index").to_numpy(), frames.column("timestamp").to_numpy()):
        if int(episode) not in episodes.index:
            raise ValueError(must_be(f"episode {int(episode)} of the frames", f"listed in {where}", "absent", HINT))
        row = episodes.loc[int(episode)]
        path = root / template.format(video_key=key, chunk_index=int(row[f"videos/{key}/chunk_index"]),
                                      file_index=int(row[f"videos/{key}/file_index"]))
        if path not in decoded:
            decoded[path] = _decode(path)
        number = int(round((float(row[f"videos/{key}/from_timestamp"]) + float(t)) * fps))
        if number >= len(decoded[path]):
            raise ValueError(must_be(f"frame {number} of {path.name}", f"in the video ({len(decoded[path])} "
                                     "frames decoded)", "past its end", HINT))
        out.append(decoded[path][number])
    return out


def _decode(path: Path) -> list[np.ndarray]:
    """Every frame of the file, in order, (H, W, 3) RGB or (H, W) gray uint8: PyAV where installed, else OpenCV."""
    if not path.is_file():
        raise FileNotFoundError(must_be("video file", "present", str(path), "The dataset is incomplete; copy "
                                        "its videos/ folder too."))
    try:
        import av
    except ImportError:
        av = None
    images, why = _decode_pyav(av, path) if av is not None else _decode_opencv(path)
    if not images:
        decoder = "PyAV" if av is not None else "the installed OpenCV/FFmpeg (PyAV is not installed)"
        raise ValueError(must_be(f"video {path.name}", f"decodable by {decoder}", why or "no frame decoded", HINT))
    return images


GRAY = ("gray", "gray8", "gray10le", "gray12le", "gray16le")   # FFmpeg's gray pixel formats: decoded as 8-bit gray


def _decode_pyav(av, path: Path) -> tuple[list[np.ndarray], str | None]:
    """(frames, why none were decoded): the first video stream, every frame converted by FFmpeg's swscale."""
    images = []
    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                return [], "no video stream"
            for frame in container.decode(video=0):
                rgb = frame.format.name not in GRAY
                images.append(frame.to_ndarray(format="rgb24" if rgb else "gray"))
    except av.FFmpegError as e:
        return [], f"{type(e).__name__} after {len(images)} frames: {str(e)[:120]}"
    return images, None


def _decode_opencv(path: Path) -> tuple[list[np.ndarray], str | None]:
    import cv2

    capture = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    images = []
    try:
        while capture.isOpened():
            ok, image = capture.read()
            if not ok:
                break
            images.append(from_opencv(image, path.name))
    finally:
        capture.release()
    return images, None
