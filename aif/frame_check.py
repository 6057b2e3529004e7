"""The checks of one tracker frame (aif/tracker.py): a rejected frame raises before the tracker's state is touched."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import torch

from bodyschema.errors import must_be


def checked_frame(perception, obs, command, dt, index: int, streams: int | None):
    """One frame's observations modality → (B, *out), command (B, Dz) rad/s or None and dt s, checked against the
    perception's models: the house error, naming frame `index`, for anything a frame may not be. streams: B of the
    frames before, None before the first belief. → (observations, command float64 or None, dt)"""
    frame = f"frame {index}"
    if not isinstance(obs, Mapping) or not obs:
        raise ValueError(must_be(f"{frame}: observations", "a dict modality → (B, *out) tensor",
                                 type(obs).__name__))
    b = streams
    models = {m.modality: m for m in perception.models}
    broken = {k for k, pi in perception.precisions.items() if np.all(np.asarray(pi) == 0)}
    missing = sorted(set(models) - set(obs) - broken)
    if set(obs) - set(models) or missing:
        raise ValueError(must_be(f"{frame}: observations keys", f"the models' modalities {sorted(models)}",
                                 sorted(obs)))
    for name, x in obs.items():
        b = b if b is not None else (x.shape[0] if isinstance(x, torch.Tensor) and x.ndim else None)
        want = (b, *models[name].output_shape)
        if not isinstance(x, torch.Tensor) or tuple(x.shape) != want or not torch.is_floating_point(x):
            got = (tuple(x.shape), str(x.dtype)) if isinstance(x, torch.Tensor) else type(x).__name__
            raise ValueError(must_be(f"{frame}: observations[{name!r}]", f"a float tensor of shape {want}", got,
                                     "One reading per stream, in the model's units (images as float in [0, 1])."))
        if not torch.isfinite(x).all():
            raise ValueError(must_be(f"{frame}: observations[{name!r}]", "finite", "NaN or inf readings"))
    if not isinstance(dt, (int, float)) or isinstance(dt, bool) or not (math.isfinite(dt) and dt > 0):
        raise ValueError(must_be(f"{frame}: dt", "a positive duration in s (the time since the last frame)", dt))
    if command is not None:
        want = (b, perception.latent_dim)
        if not isinstance(command, torch.Tensor) or tuple(command.shape) != want \
                or not torch.isfinite(command).all():
            got = tuple(command.shape) if isinstance(command, torch.Tensor) else type(command).__name__
            raise ValueError(must_be(f"{frame}: command", f"a finite joint-velocity command of shape {want} rad/s",
                                     got))
        command = command.to(torch.float64)
    return obs, command, float(dt)
