"""HDF5 sources: this project's export (datagen/exchange/export_hdf5.py, read back array for array, body and attrs)
and the demo layout robot-learning datasets use, one group per episode:

    [data/]<episode>/obs/<joint key>   (T, K) joint angles (several keys are concatenated in the order given)
    [data/]<episode>/obs/<image key>   (T, H, W[, C]) uint8 camera frames
    [data/]<episode>/obs/<ee key>      (T, 3) m end-effector position (optional, --ee-key)

Episodes are read in natural name order (demo_2 before demo_10); the store's `episode` is their index.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from bodyschema.datagen.exchange.importers.recording import EXTRA_ARRAYS, Recording
from bodyschema.errors import must_be

OWN_FORMAT = "bodyschema-hdf5"
EXPORT_HINT = "The file says it is a bodyschema export, but this was edited or lost; export the store again."


def read_hdf5(path: Path, joint_keys: tuple[str, ...], image_key: str | None, ee_key: str | None,
              images: bool) -> Recording:
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise ValueError(must_be("SOURCE", "a readable HDF5 file", f"{path.name}: {e}")) from e
    with f:
        if f.attrs.get("format") == OWN_FORMAT:
            return _own(f, path, images)
        return _demo(f, path, joint_keys, image_key, ee_key, images)


def _own(f, path: Path, images: bool) -> Recording:
    attrs = _store_attrs(f, path)
    arrays = {name: _array(f, name, path, numeric=True) for name in EXTRA_ARRAYS if name in f}
    frames = list(_array(f, "image", path)) if images and "image" in f else None
    q = _array(f, "q", path, numeric=True, ndim=2).astype(np.float64)                  # (N, Dq) rad
    names = attrs.get("joint_names")
    if not (isinstance(names, list) and len(names) == q.shape[1]):
        raise ValueError(must_be(f"store_attrs joint_names in {path.name}", f"a list of {q.shape[1]} names (one per "
                                 "column of q)", names, EXPORT_HINT))
    labels = [f"{path.name} frame {i}" for i in range(len(frames or []))]
    return Recording(q, tuple(map(str, names)), frames, labels, arrays, unit="rad", attrs=attrs, files=[path],
                     params={"format": "hdf5", "layout": OWN_FORMAT})


def _store_attrs(f, path: Path) -> dict:
    """The store's attrs a bodyschema export carries (JSON in the root attr `store_attrs`)."""
    text = f.attrs.get("store_attrs")
    try:
        attrs = json.loads(text) if isinstance(text, (str, bytes)) else None
    except ValueError:
        attrs = None
    if not isinstance(attrs, dict):
        raise ValueError(must_be(f"the root attr store_attrs of {path.name}", "the JSON object of the store's attrs",
                                 "missing" if text is None else f"{str(text)[:60]!r}", EXPORT_HINT))
    return attrs


def _array(group, key: str, path: Path, numeric: bool = False, ndim: int | None = None) -> np.ndarray:
    """The dataset `key` of `group`, read: the house error naming the file when it is a group, a scalar, text
    (numeric) or of another rank (ndim)."""
    import h5py

    node = group.get(key)
    where = f"{group.name.rstrip('/')}/{key} in {path.name}"
    if not isinstance(node, h5py.Dataset):
        raise ValueError(must_be(where, "a dataset (an array with one row per frame)",
                                 "a group" if isinstance(node, h5py.Group) else "missing"))
    if node.ndim < 1 or (ndim is not None and node.ndim != ndim):
        raise ValueError(must_be(where, f"an array of {ndim or '>= 1'} dimension(s)", f"shape {node.shape}"))
    values = node[()]
    if numeric and values.dtype.kind not in "biuf":
        raise ValueError(must_be(where, "numbers", f"dtype {values.dtype}"))
    return values


def _natural(name: str) -> list:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name)]


def _episodes(f) -> list:
    """The groups holding an `obs` group, at the top level or one level down (robomimic's data/demo_i)."""
    import h5py

    found = []
    for group in (f, *(g for g in f.values() if isinstance(g, h5py.Group))):
        found += [g for g in group.values() if isinstance(g, h5py.Group) and isinstance(g.get("obs"), h5py.Group)]
    if not found:
        raise ValueError(must_be("SOURCE", f"a {OWN_FORMAT} export or episodes with an obs group "
                                 "(<episode>/obs/<key>)", f"top-level keys {sorted(f.keys())[:10]}"))
    return sorted(found, key=lambda g: _natural(g.name))


def _demo(f, path: Path, joint_keys, image_key, ee_key, images: bool) -> Recording:
    import h5py

    episodes = _episodes(f)
    obs_keys = sorted(episodes[0]["obs"].keys())
    if not joint_keys:
        raise ValueError(must_be("--joint-key", "the obs key(s) of the joint angles", "none",
                                 f"Keys in {episodes[0].name}/obs: {obs_keys}."))
    if images and image_key is None:
        first = episodes[0]["obs"]
        candidates = [k for k in obs_keys if isinstance(first.get(k), h5py.Dataset) and first[k].dtype == np.uint8
                      and first[k].ndim in (3, 4)]
        if len(candidates) != 1:
            raise ValueError(must_be("--image-key", "the obs key of the camera frames", f"{len(candidates)} image "
                                     f"keys {candidates}", "Name one, or pass --no-images."))
        image_key = candidates[0]
    q, frames, names, ee, episode = [], [], [], [], []
    for index, group in enumerate(episodes):
        obs = group["obs"]
        wanted = [*joint_keys, *([image_key] if images else []), *([ee_key] if ee_key else [])]
        unknown = [k for k in wanted if k not in obs]
        if unknown:
            raise ValueError(must_be(f"keys {unknown}", f"in {group.name}/obs", sorted(obs.keys()),
                                     "Pass --joint-key / --image-key / --ee-key among them."))
        parts = [_array(obs, k, path, numeric=True) for k in joint_keys]
        parts = [np.asarray(p, float).reshape(len(p), int(np.prod(p.shape[1:]))) for p in parts]
        if len({len(p) for p in parts}) != 1:
            raise ValueError(must_be(f"{group.name}/obs joint keys {list(joint_keys)} in {path.name}",
                                     "of one length", [len(p) for p in parts]))
        if not len(parts[0]):
            raise ValueError(must_be(f"episode {group.name} of {path.name}", "at least one frame", "0 frames",
                                     "Drop the empty episode from the file."))
        q.append(np.concatenate(parts, axis=1))
        episode.append(np.full(len(q[-1]), index, np.int32))
        if images:
            pictures = _array(obs, image_key, path)
            frames += list(pictures)
            names += [f"{path.name}{group.name} frame {i}" for i in range(len(pictures))]
        if ee_key:
            ee.append(_array(obs, ee_key, path, numeric=True).astype(float))
            if ee[-1].shape[1:] != (3,):
                raise ValueError(must_be(f"{group.name}/obs/{ee_key} in {path.name}", "(T, 3) m: x, y, z per frame",
                                         f"shape {ee[-1].shape}", "Pass as --ee-key the ee position key."))
    arrays = {"episode": np.concatenate(episode)}
    if ee_key:
        arrays["ee_xyz"] = np.concatenate(ee)
    return Recording(np.concatenate(q), None, frames if images else None, names, arrays, files=[path],
                     params={"format": "hdf5", "layout": "demo", "episodes": len(episodes),
                             "joint_keys": list(joint_keys), "image_key": image_key, "ee_key": ee_key},
                     dropped=_not_read(episodes[0], {*joint_keys, image_key, ee_key}))


def _not_read(episode, read: set) -> dict[str, str]:
    """What an episode holds besides the obs keys read (other obs keys; actions, rewards, states beside obs): the
    demo layout names no joint-angle commands (robomimic's actions are end-effector deltas), so nothing more is kept."""
    out = {f"obs/{k}": "not asked for (--joint-key, --image-key, --ee-key)" for k in episode["obs"] if k not in read}
    out |= {k: "no store array of it (not a joint-angle reading)" for k in episode if k != "obs"}
    return out
