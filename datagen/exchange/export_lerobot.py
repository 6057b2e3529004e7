"""A dataset store in LeRobot's on-disk dataset layout, codebase v3.0 (lerobot ≥ 0.4), written with pyarrow.

    meta/info.json                          codebase_version, robot_type, fps, totals, splits, data_path, features
                                            ({key: {dtype, shape, names}}, LeRobot's five index columns included)
    meta/stats.json                         per feature: min, max, mean, std, count, q01, q10, q50, q90, q99 as
                                            LeRobot writes them (images per channel, in [0, 1]; export_lerobot_stats)
    meta/tasks.parquet                      one task (the sampler), index = task text, column task_index
    meta/episodes/chunk-000/file-000.parquet  per episode: length, tasks, dataset_from/to_index, data/chunk/file_index
    data/chunk-XXX/file-YYY.parquet         the frames, whole episodes per file (≤ ~100 MB each)
    meta/bodyschema.json                    ours: units, the body spec, the store's attrs, which array is which key

Keys: q → observation.state (names = joint names), qvel → observation.velocity, ee_xyz / ee_pixel / touch →
observation.<name>, jacobian (3, Dq) → observation.jacobian flattened to 3·Dq values named "x/<joint>" (LeRobot's
vector features are 1-D), image → observation.images.<camera> (dtype "image": PNG bytes in the parquet, as
LeRobot's image features are stored; no video: that needs an AV1/H.264 encoder). A feature of shape [1] (touch, a
1-joint state) is a plain scalar column: LeRobot's reader maps shape (1,) to a `datasets.Value`, not a list
(`get_hf_features_from_features`), and fails to cast a one-element list. A babbling store gives its episodes and
time stamps (fps = its record rate); independent poses (uniform sampler) become one episode at fps 1, frame i at i s.
`action` (Dq joint angles, rad) is the command given at each frame: a babbling store's `target` (the servo targets
the arm is driven toward from that frame on); a store without commands (independent poses, or a babbling store made
before datagen recorded its targets) gets the next frame's observation.state in the same episode, an episode's last
frame holding its own, so the next pose reached is the command a policy trained on it learns to give. The format
has no units and no field for how `action` was made; both are in meta/bodyschema.json (`action`: how, `arrays`:
"action" → "target" when it is the store's array).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import zarr

from bodyschema.base import modalities
from bodyschema.datagen.exchange.export_lerobot_stats import LeRobotStats
from bodyschema.datagen.store.integrity import data_arrays
from bodyschema.datagen.store.reader import attrs_json, feature, read, store_body
from bodyschema.datagen.store.rows import row_blocks
from bodyschema.errors import must_be

FORMAT = "bodyschema-lerobot"
SIZE_FACTOR = 3                         # output / the store's compressed bytes: 2.6 measured (1500 planar2 images)
CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000                      # files per chunk directory (LeRobot's default)
DATA_FILE_MB = 100                      # target size of one data file (LeRobot's default)
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
STATE = {"q": "observation.state", "qvel": "observation.velocity"}    # the joints' keys, LeRobot's names
ACTION = "action"
COMMANDS = "target"                     # the store array holding the commands, where it has one (babbling)
ACTION_NOTES = {
    COMMANDS: "the servo targets (rad) the babbling arm is driven toward from this frame on: the store's `target`.",
    "q": "the next frame's observation.state (rad) in the same episode; an episode's last frame holds its own. The "
         "store records the poses reached, not the commands, so the next pose stands in."}
INDEX_FEATURES = {"timestamp": "float32", "frame_index": "int64", "episode_index": "int64", "index": "int64",
                  "task_index": "int64"}


def write_lerobot(root: zarr.Group, out: Path) -> None:
    attrs = dict(root.attrs)
    n = int(root["q"].shape[0])
    episodes = episode_ranges(np.asarray(root["episode"][:]) if "episode" in root.array_keys() else None, n)
    fps = float(attrs.get("sampler_params", {}).get("record_hz") or 1.0) if "t" in root.array_keys() else 1.0
    fps = int(fps) if fps.is_integer() else fps                        # LeRobot's fps is an int where it can be
    feats = lerobot_features(root)
    task = f"{attrs.get('sampler')} sampling of the {attrs.get('robot')} joints"
    stats = LeRobotStats()
    files = _files(episodes, _row_bytes(root))
    for file_no, eps in enumerate(files):
        path = out / DATA_PATH.format(chunk_index=file_no // CHUNKS_SIZE, file_index=file_no % CHUNKS_SIZE)
        _write_data_file(root, path, [(i, episodes[i]) for i in eps], fps, feats, stats)
    _write_meta(out, attrs, feats, episodes, files, fps, task, stats, root)


def lerobot_features(root: zarr.Group) -> dict[str, dict[str, Any]]:
    """LeRobot's `features`: {key: {dtype, shape, names}} for the store's arrays, then the five index columns."""
    out = {}
    names = set(data_arrays(root))
    for name, key in keys().items():
        if name in names:
            f = feature(root, name)
            out[key] = {"dtype": f["dtype"], "shape": [int(np.prod(f["shape"]))], "names": _names(root, name, f)}
    out[ACTION] = dict(out[STATE["q"]])               # a joint-angle command per frame: same dtype, width, names
    for camera in modalities.images_in(names):
        h, w, *c = feature(root, camera)["shape"]
        out[image_key(root, camera)] = {"dtype": "image", "shape": [h, w, c[0] if c else 1],
                                        "names": ["height", "width", "channels"]}
    out.update({k: {"dtype": dtype, "shape": [1], "names": None} for k, dtype in INDEX_FEATURES.items()})
    return out


def keys() -> dict[str, str]:
    """Store array → LeRobot key of every vector feature, in the export's column order (the store's)."""
    sensors = [m.name for m in modalities.MODALITIES.values() if m.sensor]
    rows = [m for m in modalities.stored(False, sensors) if m.store_array not in STATE]
    return STATE | {m.store_array: f"observation.{m.name}" for m in rows}


def image_key(root: zarr.Group, camera: str = modalities.IMAGE) -> str:
    """observation.images.<camera> of the store array `camera` (the robot's own camera: its attrs name)."""
    return f"observation.images.{modalities.get(camera).camera or root.attrs.get('camera_name') or 'camera'}"


def _names(root: zarr.Group, name: str, f: dict) -> list[str]:
    joints = list(root.attrs["joint_names"])
    if name in ("q", "qvel"):
        return joints
    if name == "jacobian":                 # (3, Dq) row-major: d(x|y|z)/d(joint)
        return [f"{axis}/{joint}" for axis in "xyz" for joint in joints]
    return list(f["names"]) if len(f["names"]) == f["shape"][0] else [f"{name}_{i}" for i in range(f["shape"][0])]


def episode_ranges(episode: np.ndarray | None, n: int) -> list[tuple[int, int]]:
    """[(from, to)] row ranges, one per episode in row order; one episode of all rows without `episode`."""
    if episode is None or n == 0:
        return [(0, n)]
    starts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]])        # where the id changes
    ids = episode[starts]
    if len(np.unique(ids)) != len(ids):
        raise ValueError(must_be("the store's episodes", "contiguous runs of rows (LeRobot stores an episode as a "
                                 "row range)", f"episode ids recurring: {ids[:10].tolist()}…"))
    return list(zip(starts.tolist(), [*starts[1:].tolist(), n]))


def _row_bytes(root: zarr.Group) -> int:
    return sum(int(np.prod(root[name].shape[1:], dtype=np.int64)) * root[name].dtype.itemsize
               for name in data_arrays(root))


def _files(episodes: list[tuple[int, int]], row_bytes: int) -> list[list[int]]:
    """Episode indices per data file: whole episodes, a new file once ~DATA_FILE_MB (raw bytes) is reached."""
    limit = max(1, int(DATA_FILE_MB * 2 ** 20 // max(row_bytes, 1)))
    files, rows = [[]], 0
    for i, (start, stop) in enumerate(episodes):
        if files[-1] and rows + (stop - start) > limit:
            files.append([])
            rows = 0
        files[-1].append(i)
        rows += stop - start
    return files


def _write_data_file(root: zarr.Group, path: Path, eps: list[tuple[int, tuple[int, int]]], fps: float,
                     feats: dict, stats: "LeRobotStats") -> None:
    """One parquet file holding the frames of episodes `eps` = [(episode_index, (from, to))], a row group per read."""
    import pyarrow.parquet as pq

    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {b"huggingface": json.dumps({"info": {"features": _hf_features(feats)}}).encode()}
    writer = None
    for episode_index, (start, stop) in eps:
        for a, b in row_blocks(stop - start):
            table = _frames(root, (start + a, start + b), (episode_index, stop), a, fps, feats, stats)
            table = table.replace_schema_metadata(meta)   # so `datasets` decodes the image column as images
            writer = writer or pq.ParquetWriter(str(path), table.schema)
            writer.write_table(table)
    if writer is not None:
        writer.close()


def _frames(root: zarr.Group, rows: tuple[int, int], episode: tuple[int, int], first_frame: int, fps: float,
            feats: dict, stats: "LeRobotStats"):
    """Rows [start, stop) of the store, inside the episode (index, its end row), as an arrow table with LeRobot's
    columns."""
    import pyarrow as pa

    (start, stop), (episode_index, episode_stop) = rows, episode
    frame = np.arange(first_frame, first_frame + stop - start, dtype=np.int64)        # (b,)
    t = read(root, "t", start, stop).astype(np.float32) if "t" in root.array_keys() else (frame / fps)
    columns = {}
    for name, key in keys().items():
        if key in feats:
            columns[key] = _vector_column(key, read(root, name, start, stop).reshape(stop - start, -1), stats)
    columns[ACTION] = _vector_column(ACTION, _action(root, start, stop, episode_stop), stats)
    for camera in modalities.images_in(root.array_keys()):
        images = read(root, camera, start, stop)                                      # (b, H, W[, C]) uint8
        stats.add_images(image_key(root, camera), images)
        columns[image_key(root, camera)] = pa.array([{"bytes": _png(img), "path": None} for img in images],
                                            type=pa.struct([("bytes", pa.binary()), ("path", pa.string())]))
    index = {"timestamp": np.asarray(t, np.float32), "frame_index": frame,
             "episode_index": np.full(len(frame), episode_index, np.int64),
             "index": np.arange(start, stop, dtype=np.int64), "task_index": np.zeros(len(frame), np.int64)}
    for key, values in index.items():
        stats.add(key, values[:, None])
        columns[key] = pa.array(values)
    return pa.table(columns)


def action_source(root: zarr.Group) -> str:
    """The store array `action` is made of: the commands where the store has them, else q (the next frame's)."""
    return COMMANDS if COMMANDS in root.array_keys() else "q"


def _action(root: zarr.Group, start: int, stop: int, episode_stop: int) -> np.ndarray:
    """`action` of rows [start, stop) (b, Dq) rad: the recorded commands, else the next state."""
    if action_source(root) == COMMANDS:
        return read(root, COMMANDS, start, stop)
    return _next_state(root, start, stop, episode_stop)


def _next_state(root: zarr.Group, start: int, stop: int, episode_stop: int) -> np.ndarray:
    """`action` of rows [start, stop): q of the row after each, the episode's last row (episode_stop - 1) its own."""
    q_next = read(root, "q", start + 1, min(stop + 1, episode_stop))                 # (b or b - 1, Dq)
    if stop == episode_stop:
        q_next = np.concatenate([q_next, read(root, "q", stop - 1, stop)])
    return q_next                                                                    # (b, Dq)


def _vector_column(key: str, values: np.ndarray, stats: "LeRobotStats"):
    """(b, k) values as LeRobot reads a feature of shape [k]: one scalar per row when k = 1, else a k-list."""
    import pyarrow as pa

    stats.add(key, values)
    if values.shape[1] == 1:
        return pa.array(values[:, 0])
    return pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1)), values.shape[1])


def _png(image: np.ndarray) -> bytes:
    bgr = image if image.ndim == 2 or image.shape[2] == 1 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", bgr)
    if not ok:
        raise ValueError(must_be("image", "encodable as PNG", f"array {image.shape} {image.dtype}"))
    return buf.tobytes()


def _hf_features(feats: dict) -> dict:
    """The `datasets` library's feature types of the columns (what LeRobot's loader casts them to)."""
    out = {}
    for key, f in feats.items():
        if f["dtype"] == "image":
            out[key] = {"_type": "Image"}
        elif f["shape"] == [1]:                          # LeRobot: shape (1,) is a scalar Value, never a list
            out[key] = {"dtype": f["dtype"], "_type": "Value"}
        else:
            out[key] = {"feature": {"dtype": f["dtype"], "_type": "Value"}, "length": f["shape"][0],
                        "_type": "Sequence"}
    return out


def _write_meta(out: Path, attrs: dict, feats: dict, episodes: list[tuple[int, int]], files: list[list[int]],
                fps: float, task: str, stats: LeRobotStats, root: zarr.Group) -> None:
    import pandas as pd

    meta = out / "meta"
    meta.mkdir(parents=True, exist_ok=True)
    info = {"codebase_version": CODEBASE_VERSION, "robot_type": attrs.get("robot"),
            "total_episodes": len(episodes), "total_frames": episodes[-1][1] if episodes else 0, "total_tasks": 1,
            "chunks_size": CHUNKS_SIZE, "data_files_size_in_mb": DATA_FILE_MB, "video_files_size_in_mb": 500,
            "fps": fps, "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH, "video_path": None,
            "features": feats}
    (meta / "info.json").write_text(json.dumps(info, indent=4))
    (meta / "stats.json").write_text(json.dumps(stats.as_json(), indent=4))
    pd.DataFrame({"task_index": [0]}, index=pd.Index([task], name="task")).to_parquet(meta / "tasks.parquet")
    file_of = {i: f for f, eps in enumerate(files) for i in eps}
    rows = [{"episode_index": i, "tasks": [task], "length": stop - start,
             "data/chunk_index": file_of[i] // CHUNKS_SIZE, "data/file_index": file_of[i] % CHUNKS_SIZE,
             "dataset_from_index": start, "dataset_to_index": stop,
             "meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0} for i, (start, stop) in enumerate(episodes)]
    (out / EPISODES_PATH).parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_parquet(out / EPISODES_PATH, index=False)
    vectors = {key: name for name, key in keys().items() if key in feats}
    units = {key: feature(root, name)["unit"] for key, name in vectors.items()} | {ACTION: "rad"}
    arrays = dict(vectors)
    if action_source(root) == COMMANDS:
        arrays[ACTION] = COMMANDS                  # the importer reads it back into the store's array
    for camera in modalities.images_in(root.array_keys()):
        units[image_key(root, camera)], arrays[image_key(root, camera)] = "intensity 0-255", camera
    ours = {"format": FORMAT, "units": units, "body": store_body(root), "arrays": arrays,
            "frames": "a babbling trajectory" if "t" in root.array_keys() else "independent poses (fps 1: frame i "
            "at i s)", "action": ACTION_NOTES[action_source(root)], "store_attrs": json.loads(attrs_json(root))}
    (meta / "bodyschema.json").write_text(json.dumps(ours, indent=2))
