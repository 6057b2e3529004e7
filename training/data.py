"""Training data from a dataset store, split train/validation; datagen reads the store (`datagen.store.reader`).

The store is checked first (`check_store` lists every problem at once: the datagen validator's and the arrays the
run asks for; an invalid or incomplete store is refused). The joint angles `q` and the modality arrays are read
whole, and the store's content digest (`store_digest`) is logged to MLflow and part of the run's identity.
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

from bodyschema.datagen.store.reader import check_store, read_arrays, store_body, store_digest
from bodyschema.errors import must_be
from bodyschema.models.body_robot import attrs_source
from bodyschema.models.scaling import IMAGE_SCALE, BodySpec


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


def validation_digest(data: Dataset) -> str:
    """sha256 of the store's digest and its held-out row indices: the validation data a val_rmse was measured on.
    Two versions' scores compare (the champion rule) only when this agrees."""
    rows = np.ascontiguousarray(data.val.rows, dtype="<i8")
    return hashlib.sha256(data.sha256.encode() + b"\0" + rows.tobytes()).hexdigest()


def as_float(x: np.ndarray | torch.Tensor) -> torch.Tensor:
    """A batch as float32 tensor: uint8 images → [0, 1], everything else unchanged in value."""
    t = torch.as_tensor(x)
    return t.float().div_(IMAGE_SCALE) if t.dtype == torch.uint8 else t.float()


def load_dataset(path: str | Path, modality: str | tuple[str, ...], *, val_fraction: float = 0.2, seed: int = 0,
                 max_train: int | None = None, progress: bool = False) -> Dataset:
    """Check, read and split a store for one modality or several ("ee_xyz,image" or a tuple).

    Raises the house ValueError listing every problem of a bad store.
    """
    path = Path(path)
    modalities = tuple(m.strip() for m in modality.split(",")) if isinstance(modality, str) else tuple(modality)
    store = check_store(path, ("q", *modalities), what="data",
                        hints=dict.fromkeys(modalities, "Choose --modality among the store's arrays, or remake the "
                                            "store (`datagen --overwrite`, the same poses) if it was made before "
                                            "datagen recorded this one."))
    if store.problems:
        raise ValueError(f"Dataset {str(path)!r} cannot be used for training:\n - " + "\n - ".join(store.problems))
    root, attrs = store.root, store.attrs
    names = ["q", *modalities] + (["episode"] if "episode" in root.array_keys() else [])
    arrays = read_arrays(root, names, progress)
    q = arrays["q"].astype(np.float32, copy=False)
    xs = {m: arrays[m] if arrays[m].dtype == np.uint8 else arrays[m].astype(np.float32, copy=False)
          for m in modalities}
    rng = np.random.default_rng(seed)
    train_rows, val_rows, split_by = split_rows(arrays.get("episode"), len(q), val_fraction, rng)
    if max_train is not None and len(train_rows) > max_train:
        train_rows = np.sort(rng.choice(train_rows, size=max_train, replace=False))
    whole = Split(q, xs, np.arange(len(q)))
    body = BodySpec.from_dict({**store_body(root), "source": attrs_source(attrs)})
    return Dataset(path, modalities, body, attrs, whole.take(train_rows), whole.take(val_rows), store_digest(root),
                   split_by)


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
