"""A LeRobot dataset, codebase v3.0 (the inverse of datagen/exchange/export_lerobot.py): meta/info.json, the frames in
data/chunk-*/file-*.parquet, images as PNG bytes in the parquet or as video files (video.py: PyAV where installed,
which decodes every codec LeRobot writes, else OpenCV's FFmpeg where it has the codec; else the house error).

Joint angles: `observation.state` (or --joint-key), its names from the features. This project's export also
brings back velocity, ee_xyz, ee_pixel, jacobian (3·Dq values → (3, Dq)), touch, its units and store attrs
(meta/bodyschema.json); a foreign dataset gives the state, the image and `episode_index` / `timestamp`. A feature of
shape [1] may be a list or a scalar column (LeRobot writes the scalar); both come back as (N, 1). `action` comes back
as the store's `target` where meta/bodyschema.json maps it to that array (a babbling store's servo targets; else the
export derived it from the state, the next frame's, which the store does not keep), and in a foreign dataset where its
names are the state's joints (goal positions, as LeRobot's arms record them). Every feature not imported is listed in
`Recording.dropped` with the reason, and said in one line by the import.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bodyschema.datagen.exchange.export_lerobot import keys
from bodyschema.datagen.exchange.importers.folder_csv import from_opencv
from bodyschema.datagen.exchange.importers.recording import Recording
from bodyschema.errors import must_be

OWN_FORMAT = "bodyschema-lerobot"
ACTION, COMMANDS = "action", "target"     # LeRobot's command column; the store array it comes from, when one does
INDEX_COLUMNS = ("timestamp", "frame_index", "episode_index", "index", "task_index")   # LeRobot's, per frame


def read_lerobot(root: Path, joint_keys: tuple[str, ...], image_key: str | None, images: bool) -> Recording:
    info = _info(root)
    ours = _ours(root)
    frames = _frames(root)
    state_key = joint_keys[0] if joint_keys else "observation.state"
    feats = info["features"]
    if state_key not in feats or state_key not in frames.column_names:
        raise ValueError(must_be(f"joint key {state_key!r}", "a feature of the dataset", sorted(feats),
                                 "Pass --joint-key with the feature of the joint angles."))
    q = _vectors(frames, state_key, root)                                            # (N, K)
    arrays = _own_arrays(frames, q.shape[1], ours.get("arrays", {}), root) if ours else {}
    recorded = (ours or {}).get("store_attrs", {}).get("features")
    if recorded is None or "episode" in recorded:
        arrays["episode"] = _column(frames, "episode_index", root)
    if recorded is None or "t" in recorded:
        arrays["t"] = _column(frames, "timestamp", root)
    key = _image_key(feats, image_key) if images else None
    pictures = _images(root, info, frames, key) if key else None
    columns = _names(feats[state_key], q.shape[1])
    dropped = {}
    if ours is None and ACTION in feats and ACTION in frames.column_names and state_key != ACTION:
        action, why = _foreign_action(frames, feats, state_key, columns, root)
        if action is not None:
            arrays[COMMANDS] = action
        else:
            dropped[ACTION] = why
    used = {state_key, *INDEX_COLUMNS, *([key] if key else []), *(own_arrays() if ours else ()),
            *([ACTION] if COMMANDS in arrays else [])}
    for name in feats:
        if name not in used and name not in dropped:
            dropped[name] = _why_dropped(name, feats[name], ours, images)
    return Recording(q, columns, pictures,
                     [f"{root.name} frame {i}" for i in range(len(q))] if key else [], arrays,
                     unit="rad" if ours else None, attrs=(ours or {}).get("store_attrs", {}),
                     files=[p for p in root.rglob("*") if p.is_file()],
                     params={"format": "lerobot", "codebase_version": info["codebase_version"],
                             "state_key": state_key, "image_key": key, "fps": info.get("fps")},
                     dropped=dropped)


def _foreign_action(frames, feats: dict, state_key: str, columns: tuple[str, ...] | None,
                    root: Path) -> tuple[np.ndarray | None, str]:
    """(`action` as the store's `target`, with q's columns, in q's unit; or None and why not). A LeRobot `action` is
    kept where it commands the state's joints: its names are the state's (any order), so each value is a target angle
    of a joint q reads, in q's unit (LeRobot's arms record goal positions this way). Any other action (fewer or other
    names, none, end-effector or velocity commands) has no place in the store."""
    names = _names(feats[ACTION], _width(feats[ACTION]))
    if columns is None or names is None:
        return None, (f"not the store's `target`: the joints it commands are not named (names of {state_key}: "
                      f"{columns}, of {ACTION}: {names})")
    if sorted(names) != sorted(columns):
        return None, f"not the store's `target`: it commands {list(names)}, not the joints of {state_key}"
    values = _vectors(frames, ACTION, root)                                              # (N, K) names' order
    if values.shape[1] != len(names):
        return None, f"not the store's `target`: {values.shape[1]} values per frame for {len(names)} names"
    return values[:, [names.index(c) for c in columns]], ""


def _width(feature: dict) -> int:
    shape = feature.get("shape")
    return int(np.prod(shape)) if isinstance(shape, list) and all(isinstance(v, int) for v in shape) else -1


def _why_dropped(name: str, feature: dict, ours: dict | None, images: bool) -> str:
    if feature.get("dtype") in ("image", "video"):
        return "--no-images" if not images else "another camera (--image-key picks one)"
    if ours is not None and name == ACTION:
        return "made by the export from the state (the next frame's), which the store does not keep"
    return "no store array of it"


def _info(root: Path) -> dict:
    path = root / "meta" / "info.json"
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(must_be("SOURCE", "a LeRobot dataset with a readable meta/info.json", str(root))) from e
    if not isinstance(info, dict):
        raise ValueError(must_be(f"{path}", "a JSON object (LeRobot's info)", type(info).__name__))
    version = str(info.get("codebase_version"))
    if not version.startswith("v3"):
        raise ValueError(must_be("the LeRobot codebase_version", "v3.0", version,
                                 "Convert older datasets with LeRobot's v2.1 → v3.0 script."))
    feats = info.get("features")
    if not isinstance(feats, dict) or not all(isinstance(f, dict) for f in feats.values()):
        got = type(feats).__name__ if not isinstance(feats, dict) else next(
            f"{k!r}: {type(f).__name__}" for k, f in feats.items() if not isinstance(f, dict))
        raise ValueError(must_be(f"features in {path}", "an object of features {key: {dtype, shape, names}}", got,
                                 "Rewrite meta/info.json as LeRobot writes it."))
    return info


def _ours(root: Path) -> dict | None:
    path = root / "meta" / "bodyschema.json"
    if not path.is_file():
        return None
    try:
        ours = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(must_be(f"{path}", "readable JSON (this project's export record)", str(e)[:80])) from None
    if not isinstance(ours, dict):
        raise ValueError(must_be(f"{path}", f"a JSON object (format {OWN_FORMAT!r})", type(ours).__name__,
                                 "Remove the file to import the dataset as a foreign one, or export it again."))
    if ours.get("format") != OWN_FORMAT:
        return None
    for key, kind in (("arrays", dict), ("store_attrs", dict)):
        if not isinstance(ours.get(key, {}), kind):
            raise ValueError(must_be(f"{key} in {path}", f"a JSON {kind.__name__}", type(ours[key]).__name__,
                                     "Export the store again."))
    return ours


def _frames(root: Path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    files = sorted((root / "data").glob("chunk-*/file-*.parquet"))
    if not files:
        raise ValueError(must_be("SOURCE", "a LeRobot dataset with data/chunk-*/file-*.parquet", str(root)))
    try:
        table = pa.concat_tables([pq.read_table(p) for p in files])
    except (pa.ArrowException, OSError) as e:
        raise ValueError(must_be(f"the parquet files of {root / 'data'}", "readable and of one schema",
                                 str(e).splitlines()[0][:120])) from None
    return table.take(np.argsort(_column(table, "index", root), kind="stable"))


def _column(frames, key: str, root: Path) -> np.ndarray:
    """A scalar numeric column LeRobot writes for every frame (index, episode_index, timestamp)."""
    import pyarrow as pa

    if key not in frames.column_names:
        raise ValueError(must_be(f"the {key!r} column of the frames in {root / 'data'}",
                                 "present (LeRobot writes one)", f"absent; columns {frames.column_names[:12]}"))
    column = frames.column(key)
    if not (pa.types.is_integer(column.type) or pa.types.is_floating(column.type)):
        raise ValueError(must_be(f"the {key!r} column of {root / 'data'}", "numbers", str(column.type)))
    return column.to_numpy()


def _vectors(frames, key: str, root: Path) -> np.ndarray:
    """A feature's column as (N, k): a list column (shape [k]) or a scalar one (shape [1], as LeRobot writes it)."""
    import pyarrow as pa

    values = frames.column(key).combine_chunks()
    is_list = any(test(values.type) for test in (pa.types.is_list, pa.types.is_large_list,
                                                 pa.types.is_fixed_size_list))
    flat = values.flatten() if is_list else values
    if not (pa.types.is_integer(flat.type) or pa.types.is_floating(flat.type)):
        raise ValueError(must_be(f"the {key!r} column of {root / 'data'}", "numbers (or lists of numbers)",
                                 str(values.type)))
    flat = flat.to_numpy(zero_copy_only=False)
    if len(values) and flat.size % len(values):
        raise ValueError(must_be(f"the {key!r} column of {root / 'data'}", "lists of one length",
                                 f"{flat.size} values in {len(values)} rows"))
    return np.asarray(flat, float).reshape(len(values), -1)


def _names(feature: dict, k: int) -> tuple[str, ...] | None:
    names = feature.get("names")
    if isinstance(names, dict):                      # LeRobot also writes {"motors": [...]}
        names = next(iter(names.values()), None)
    return tuple(map(str, names)) if isinstance(names, list) and len(names) == k else None


def own_arrays() -> dict[str, str]:
    """LeRobot key → store array of the vector features the export writes besides the state (export_lerobot.keys)."""
    return {key: name for name, key in keys().items() if name != "q"}


def _own_arrays(frames, dq: int, mapping: dict[str, str], root: Path) -> dict[str, np.ndarray]:
    """The store arrays this project's export wrote besides q and images (`mapping`: meta's key → array)."""
    out = {}
    if mapping.get(ACTION) == COMMANDS and ACTION in frames.column_names:
        out[COMMANDS] = _vectors(frames, ACTION, root)                         # (N, Dq) rad, the servo targets
    for key, name in own_arrays().items():
        if key in frames.column_names:
            values = _vectors(frames, key, root)
            out[name] = values.reshape(len(values), 3, dq) if name == "jacobian" else values
    return out


def _image_key(feats: dict, key: str | None) -> str | None:
    visual = [k for k, f in feats.items() if f.get("dtype") in ("image", "video")]
    if key is not None:
        if key not in visual:
            raise ValueError(must_be("--image-key", f"one of the image features {visual}", key))
        return key
    if len(visual) > 1:
        raise ValueError(must_be("--image-key", "named when there are several cameras", None,
                                 f"Image features: {visual}; or pass --no-images."))
    return visual[0] if visual else None


def _images(root: Path, info: dict, frames, key: str) -> list[np.ndarray]:
    if info["features"][key]["dtype"] == "image":
        import cv2
        cells = frames.column(key).to_pylist()
        return [from_opencv(_decoded(cv2, cell, i), f"{root.name} frame {i}") for i, cell in enumerate(cells)]
    from bodyschema.datagen.exchange.importers.video import video_frames
    return video_frames(root, info, frames, key)


def _decoded(cv2, cell: dict | None, i: int) -> np.ndarray:
    data = (cell or {}).get("bytes")
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if image is None:
        raise ValueError(must_be(f"image of frame {i}", "encoded bytes (PNG, JPEG) in the parquet", "none"))
    return image
