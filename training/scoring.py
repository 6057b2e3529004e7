"""How a trained model is scored: held-out and (a seeded subset of) training predictions against the data, in the
model's output units (joint degrees for an image encoder), and the held-out prediction plot of each score.

`val_rmse` (RMSE over all output elements) decides the champion; a non-finite one is a diverged fit and stops the run
before anything is registered. `train` and a sweep trial score with the same functions, so their numbers compare.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from bodyschema.aif.precisions import sensor_precision
from bodyschema.base import modalities
from bodyschema.errors import must_be
from bodyschema.training import plots
from bodyschema.training.data import Dataset, Split, as_float
from bodyschema.training.model_card import metric_name
from bodyschema.training.registry import METRIC

PREDICT_BATCH = 256       # validation prediction batch: bounded memory for image decoders


def score_and_plot(member, data: Dataset, modality: str, seed: int, out: Path, prefix: str,
                    progress: bool, title: str) -> tuple[dict[str, float], dict[str, Path]]:
    """Held-out and (a subset of) training scores of one member, and its prediction plot."""
    if member.encodes:
        return _score_encoder(member, data, modality, seed, out, title)
    image = data.is_image(modality)
    dtype = torch.float32 if image else torch.float64       # GP means in float64; images: float32 is plenty
    val_pred = predict_batched(member, data.val.q, dtype=dtype, progress=progress and image, desc="scoring val")
    sub = _subset(data.train, 2000, seed)
    train_pred = predict_batched(member, sub.q, dtype=dtype, progress=progress and image, desc="scoring train")
    scores = {**score(val_pred, as_float(data.val.xs[modality]).numpy(), "val"),
              **score(train_pred, as_float(sub.xs[modality]).numpy(), "train")}
    if not math.isfinite(scores[METRIC]):
        raise FloatingPointError(f"{prefix}{METRIC} is {scores[METRIC]}: the fit diverged; nothing is registered.")
    target, stem = as_float(data.val.xs[modality]).numpy(), prefix.replace("/", "_")
    title = f"Held-out predictions: {title}"
    if image:
        plot = {f"{prefix}val_images": plots.image_grid(target, val_pred, out / f"{stem}val_images.png", title)}
    else:
        plot = {f"{prefix}val_scatter": plots.prediction_scatter(target, val_pred, out / f"{stem}val_scatter.png",
                                                                 modalities.unit(modality, "?"), title,
                                                                 plots.component_names(modality, target[0].size,
                                                                                       data.body.joint_names))}
    return scores, plot


def _score_encoder(encoder, data: Dataset, modality: str, seed: int, out: Path, title: str):
    """An encoder (image → q) is scored on the joint angles, in deg: val_rmse over all joints decides its champion."""
    sub = _subset(data.train, 2000, seed)
    splits = {"val": data.val, "train": sub}
    pred = {k: np.degrees(encoder.encode(split.xs[modality]).numpy()) for k, split in splits.items()}   # (N, Dz)
    target = {k: np.degrees(split.q) for k, split in splits.items()}
    scores = {**score(pred["val"], target["val"], "val"), **score(pred["train"], target["train"], "train"),
              **per_joint(pred["val"], target["val"], data.body.joint_names)}
    if not math.isfinite(scores[METRIC]):
        raise FloatingPointError(f"{METRIC} is {scores[METRIC]}: the fit diverged; nothing is registered.")
    path = out / "val_joints.png"
    return scores, {"val_joints": plots.prediction_scatter(target["val"], pred["val"], path, "deg",
                                                           f"Joint angles from {modality}: {title}",
                                                           names=data.body.joint_names)}


def predict_batched(model, q: np.ndarray, batch: int = PREDICT_BATCH, dtype=torch.float32, progress: bool = False,
                    desc: str = "predicting") -> np.ndarray:
    """g(q) for a whole split, in batches, as numpy (a bar over the batches when asked: seconds of images).
    # (N, Dz) → (N, *out)"""
    z = torch.as_tensor(q, dtype=dtype)
    starts = tqdm(range(0, len(z), batch), desc=desc, unit="batch", disable=not progress, leave=False)
    with torch.no_grad():
        return torch.cat([model.predict(z[i:i + batch]) for i in starts]).numpy()


def score(pred: np.ndarray, target: np.ndarray, prefix: str) -> dict[str, float]:
    """RMSE over all output elements and mean per-sample Euclidean error, both in output units."""
    err = (pred.astype(np.float64) - target).reshape(len(target), -1)            # (N, O)
    return {f"{prefix}_rmse": float(np.sqrt(np.mean(err ** 2))),
            f"{prefix}_mean_error": float(np.linalg.norm(err, axis=1).mean())}


def per_joint(pred: np.ndarray, target: np.ndarray, names) -> dict[str, float]:
    """Held-out mean |error| of each joint, in deg (`val_abs_error.<joint>`): which joints an encoder learned, where
    the Euclidean `val_mean_error` over all joints hides a roll at a guess behind the others. (N, Dz) deg each."""
    err = np.abs(pred.astype(np.float64) - target).mean(axis=0)
    # no '/' in the name: a key's part before its last '/' names its modality (TrainResult._unit)
    return {f"val_abs_error.{metric_name(name).replace('/', '_')}": float(e) for name, e in zip(names, err)}


def _subset(split: Split, n: int, seed: int) -> Split:
    """At most `n` rows of a split (seeded), for the training-set score."""
    if len(split) <= n:
        return split
    return split.take(np.sort(np.random.default_rng(seed).choice(len(split), n, replace=False)))


SENSOR_FRACTION = 0.25    # a model perceived at its sensor's precision should err by well under the sensor's σ


def sensor_warning(member, scores: dict[str, float]) -> str | None:
    """The house warning for a model perceived at its sensor's precision (the precision rule: a GP, an MDN) whose
    held-out RMSE is not well under that sensor's σ: perception would trust its errors as readings. None if fine."""
    pi = sensor_precision(member)                        # None: perceived at its own precision (aif/precisions.py)
    rmse = scores.get(METRIC)
    if pi is None or rmse is None:
        return None
    sigma, unit = pi ** -0.5, modalities.unit(member.modality, "")
    unit = f" {unit}" if unit else ""
    if rmse <= SENSOR_FRACTION * sigma:
        return None
    return must_be(f"{member.kind} of {member.modality}: held-out RMSE", f"at most {SENSOR_FRACTION:g} × the "
                   f"sensor's σ = {sigma:.3g}{unit}, the precision perception weighs it by",
                   f"{rmse:.3g}{unit} ({rmse / sigma:.2f} σ)", "Its errors will read as the body being elsewhere: "
                   "fit on more poses or longer (`datagen --n`, `--epochs`; a GP's kinematic kernel on D joints has "
                   "3^D features: give it ≥ 2 × 3^D poses), or name the precision it deserves "
                   "(`--perception.precisions`).")
