"""HDF5 sources: this project's export (datagen/export_hdf5.py, read back array for array with its body and attrs)
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

from bodyschema.datagen.importers.recording import EXTRA_ARRAYS, Recording
from bodyschema.errors import must_be

OWN_FORMAT = "bodyschema-hdf5"


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
    attrs = json.loads(f.attrs["store_attrs"])
    arrays = {name: f[name][()] for name in EXTRA_ARRAYS if name in f}
    frames = list(f["image"][()]) if images and "image" in f else None
    return Recording(f["q"][()].astype(np.float64), tuple(attrs["joint_names"]), frames,
                     [f"frame {i}" for i in range(len(frames or []))], arrays, unit="rad", attrs=attrs,
                     files=[path], params={"format": "hdf5", "layout": OWN_FORMAT})


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
    episodes = _episodes(f)
    obs_keys = sorted(episodes[0]["obs"].keys())
    if not joint_keys:
        raise ValueError(must_be("--joint-key", "the obs key(s) of the joint angles", "none",
                                 f"Keys in {episodes[0].name}/obs: {obs_keys}."))
    if images and image_key is None:
        candidates = [k for k in obs_keys if episodes[0]["obs"][k].dtype == np.uint8
                      and episodes[0]["obs"][k].ndim in (3, 4)]
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
        parts = [np.asarray(obs[k][()], float).reshape(len(obs[k]), -1) for k in joint_keys]
        if len({len(p) for p in parts}) != 1:
            raise ValueError(must_be(f"{group.name}/obs joint keys {list(joint_keys)}", "of one length",
                                     [len(p) for p in parts]))
        q.append(np.concatenate(parts, axis=1))
        episode.append(np.full(len(q[-1]), index, np.int32))
        if images:
            frames += list(obs[image_key][()])
            names += [f"{group.name} frame {i}" for i in range(len(obs[image_key]))]
        if ee_key:
            ee.append(np.asarray(obs[ee_key][()], float))
    arrays = {"episode": np.concatenate(episode)}
    if ee_key:
        arrays["ee_xyz"] = np.concatenate(ee)
    return Recording(np.concatenate(q), None, frames if images else None, names, arrays, files=[path],
                     params={"format": "hdf5", "layout": "demo", "episodes": len(episodes),
                             "joint_keys": list(joint_keys), "image_key": image_key, "ee_key": ee_key})
