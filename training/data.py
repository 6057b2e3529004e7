"""Training data from a Zarr dataset store: validated, read chunk by chunk, digested, split train/validation.

The store is validated first (`bodyschema.datagen.validate.validate_store` reports every problem at once; an
invalid or incomplete store is refused). The joint angles `q` and the modality arrays are read whole, one
chunk at a time (the sample-axis chunk is the unit the store was written in), while a sha256 of what was read
is computed on the way: the dataset's content digest, logged to MLflow and part of the run's identity.
Images stay uint8 here (4x smaller than float32) and become float in [0, 1] only at batch time (`as_float`).
The validation split holds out whole episodes when the store has `episode` (babbling trajectories: neighbouring
samples are nearly equal, so a random split would leak), else a seeded random share of the samples.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import zarr
from tqdm.auto import tqdm

from bodyschema.errors import must_be
from bodyschema.models.body_robot import attrs_source
from bodyschema.models.scaling import IMAGE_SCALE, BodySpec

DATA_ARRAYS = ("q", "ee_xyz", "ee_pixel", "image", "jacobian", "qvel", "touch")  # not bookkeeping (shard_done)


@dataclass(frozen=True)
class Split:
    q: np.ndarray                  # (N, Dq) float32 rad
    xs: dict[str, np.ndarray]      # modality -> (N, *out) float32 in output units, or uint8 for images
    rows: np.ndarray               # (N,) int64 row indices in the store

    def __len__(self) -> int:
        return len(self.q)

    @property
    def x(self) -> np.ndarray:
        """The one modality's array (single-modality datasets)."""
        if len(self.xs) != 1:
            raise ValueError(must_be("modalities", "exactly one to use `.x`", sorted(self.xs), "Use `.xs[name]`."))
        return next(iter(self.xs.values()))

    def take(self, rows: np.ndarray) -> "Split":
        return Split(self.q[rows], {m: x[rows] for m, x in self.xs.items()}, self.rows[rows])


@dataclass(frozen=True)
class Dataset:
    path: Path
    modalities: tuple[str, ...]
    body: BodySpec           # robot, joints and the sampled joint ranges (the model's latent scaling)
    attrs: dict[str, Any]    # the store's root attrs (robot, mjcf_sha256, config, ...)
    train: Split
    val: Split
    sha256: str              # content digest of the whole store (`store_digest`): one per store, any modality
    split_by: str            # "episode" or "random"

    def output_shape(self, modality: str) -> tuple[int, ...]:
        return tuple(self.train.xs[modality].shape[1:])

    def is_image(self, modality: str) -> bool:
        return self.train.xs[modality].dtype == np.uint8


def as_float(x: np.ndarray | torch.Tensor) -> torch.Tensor:
    """A batch as float32 tensor: uint8 images → [0, 1], everything else unchanged in value."""
    t = torch.as_tensor(x)
    return t.float().div_(IMAGE_SCALE) if t.dtype == torch.uint8 else t.float()


def store_problems(path: Path, modalities: tuple[str, ...]) -> list[str]:
    """Every reason `path` cannot be trained on (empty when it can): the datagen validator's findings (schema,
    completion marker, NaN, axes, ...) plus the arrays this training run asks for."""
    from bodyschema.datagen.validate import validate_store

    if not (path / "zarr.json").is_file():
        return [must_be("data", "a Zarr v3 dataset store (a directory with zarr.json)", str(path),
                        "Create one with `bodyschema datagen --out PATH`.")]
    problems = validate_store(path)
    names = sorted(zarr.open_group(str(path), mode="r", zarr_format=3).array_keys())
    for need in ("q", *modalities):
        if need not in names:
            problems.append(must_be(f"data array {need!r}", f"present (arrays: {names})", "missing",
                                    "Choose --modality among the store's arrays." if need != "q" else ""))
    return problems


def load_dataset(path: str | Path, modality: str | tuple[str, ...], *, val_fraction: float = 0.2, seed: int = 0,
                 max_train: int | None = None, progress: bool = False) -> Dataset:
    """Validate, read and split a store for one modality or several ("ee_xyz,image" or a tuple).

    Raises the house ValueError listing every problem of a bad store.
    """
    path = Path(path)
    modalities = tuple(m.strip() for m in modality.split(",")) if isinstance(modality, str) else tuple(modality)
    problems = store_problems(path, modalities)
    if problems:
        raise ValueError(f"Dataset {str(path)!r} cannot be used for training:\n - " + "\n - ".join(problems))
    root = zarr.open_group(str(path), mode="r", zarr_format=3)
    attrs = dict(root.attrs)
    names = ["q", *modalities] + (["episode"] if "episode" in root.array_keys() else [])
    arrays = {name: _read_chunked(root[name], name, hashlib.sha256(), progress) for name in names}
    q = arrays["q"].astype(np.float32, copy=False)
    xs = {m: arrays[m] if arrays[m].dtype == np.uint8 else arrays[m].astype(np.float32, copy=False)
          for m in modalities}
    rng = np.random.default_rng(seed)
    train_rows, val_rows, split_by = split_rows(arrays.get("episode"), len(q), val_fraction, rng)
    if max_train is not None and len(train_rows) > max_train:
        train_rows = np.sort(rng.choice(train_rows, size=max_train, replace=False))
    whole = Split(q, xs, np.arange(len(q)))
    return Dataset(path, modalities, body_from_attrs(attrs, q), attrs, whole.take(train_rows), whole.take(val_rows),
                   store_digest(root, progress), split_by)


def store_digest(root: zarr.Group, progress: bool = False) -> str:
    """The store's content digest, the same whichever modality a run reads from it: sha256 of every data array's
    name, dtype and shape and of the per-shard checksums datagen recorded (`shard_done`: each covers all arrays'
    rows of its shard, and `validate_store` has just recomputed them). Stores without checksums (schema 1): sha256
    of every data array read in full."""
    from bodyschema.datagen.integrity import data_arrays
    from bodyschema.datagen.store import has_checksums, shard_digests

    digest = hashlib.sha256(b"bodyschema-store;")
    names = data_arrays(root)
    for name in names:
        digest.update(f"{name}|{root[name].dtype}|{root[name].shape};".encode())
    if has_checksums(root):
        digest.update(shard_digests(root).astype("<u8").tobytes())
    else:
        for name in names:
            _read_chunked(root[name], name, digest, progress)
    return digest.hexdigest()


def split_rows(episode: np.ndarray | None, n: int, val_fraction: float,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, str]:
    """(train rows, validation rows, how): whole episodes held out when there are ≥ 2, else random rows."""
    if n < 2:
        raise ValueError(must_be("dataset size", "at least 2 samples (one to train, one to validate)", n))
    if episode is not None and len(np.unique(episode)) >= 2:
        ids, counts = np.unique(episode, return_counts=True)
        order = rng.permutation(len(ids))
        # Smallest number of shuffled episodes reaching the validation share; at least one, never all.
        k = int(np.searchsorted(np.cumsum(counts[order]), val_fraction * n)) + 1
        held = ids[order[:min(max(k, 1), len(ids) - 1)]]
        is_val = np.isin(episode, held)
        return np.flatnonzero(~is_val), np.flatnonzero(is_val), "episode"
    n_val = min(max(1, round(val_fraction * n)), n - 1)
    perm = rng.permutation(n)
    return np.sort(perm[n_val:]), np.sort(perm[:n_val]), "random"


def body_from_attrs(attrs: dict[str, Any], q: np.ndarray) -> BodySpec:
    """The model's BodySpec: robot and joints from the attrs, latent scaling from the sampled ranges (rad), and a
    robot that is not shipped carried along (the store's record and model file: `models.body_robot`)."""
    names = tuple(attrs["joint_names"])
    if len(names) != q.shape[1]:
        raise ValueError(must_be("data attrs['joint_names']", f"one name per column of q ({q.shape[1]})", list(names)))
    ranges = attrs.get("sampling_ranges")
    if ranges is not None:
        low, high = (tuple(float(r[i]) for r in ranges) for i in (0, 1))
    else:                       # older stores: the observed range of q
        low, high = tuple(map(float, q.min(axis=0))), tuple(map(float, q.max(axis=0)))
    return BodySpec(str(attrs["robot"]), names, low, high, attrs_source(attrs))


def _read_chunked(array: zarr.Array, name: str, digest, progress: bool) -> np.ndarray:
    """Read a whole array chunk by chunk along the sample axis, feeding the digest in row order."""
    n, step = array.shape[0], array.chunks[0]
    out = np.empty(array.shape, dtype=array.dtype)
    digest.update(f"{name}|{array.dtype}|{array.shape}".encode())
    starts = range(0, n, step)
    for start in tqdm(starts, desc=f"read {name}", unit="chunk", disable=not progress or len(starts) < 8):
        out[start:start + step] = array[start:start + step]
        digest.update(np.ascontiguousarray(out[start:start + step]).tobytes())
    return out
