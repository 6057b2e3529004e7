"""A tiny trainable SensoryModel for the training tests: fast, seeded, checkpointed, with injectable failures.

Random Fourier features of the scaled joints with a linear read-out, fitted by full-batch gradient descent,
one step per "epoch". The class attributes `fail_at` / `fail_with` (set by a test, not part of the config, so
the run identity is unchanged) raise at that epoch — a crash, or a kill (KeyboardInterrupt) — after the epoch's
checkpoint is written, so a second run with the same config resumes. `sleep_s` slows each epoch down, so a test
can kill a training process (or start a second one) while it is fitting.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch

from bodyschema.models.configs import ModelConfig
from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.kinds import Kind
from bodyschema.training.config import TrainConfig

N_FEATURES = 64


class Boom(RuntimeError):
    """The injected failure."""


@register_kind
class TinyModel(BaseSensoryModel):
    kind = "tiny"
    fail_at: int = -1           # epoch at which fit raises (-1: never)
    fail_with: str = "error"    # "error" → Boom, "interrupt" → KeyboardInterrupt
    sleep_s: float = 0.0        # seconds slept after each epoch's checkpoint

    def __init__(self, body, modality, output_shape, *, epochs: int = 30, lr: float = 0.5):
        super().__init__(body, modality, output_shape)
        self.epochs, self.lr = epochs, lr
        self.omega_ = self.weight_ = None
        self.epochs_run_: list[int] = []       # the epochs this process actually ran (resume tests read it)

    @property
    def is_fitted(self):
        return self.weight_ is not None

    def fit(self, q, x, *, seed=0, val=None, on_epoch=None, progress=True, checkpoint=None):
        q = torch.as_tensor(np.asarray(q), dtype=torch.float64)
        x = torch.as_tensor(np.asarray(x))
        x = (x.double() / 255.0 if x.dtype == torch.uint8 else x.double()).reshape(len(x), -1)   # (N, O)
        gen = torch.Generator().manual_seed(seed)
        self.omega_ = torch.randn(self.latent_dim, N_FEATURES, generator=gen, dtype=torch.float64) * 2.0
        weight, start = torch.zeros(N_FEATURES, x.shape[1], dtype=torch.float64), 0
        if checkpoint is not None and Path(checkpoint).is_file():
            saved = torch.load(checkpoint, weights_only=True)
            weight, start = saved["weight"], int(saved["epoch"]) + 1
        phi = self._features(q)                                                                 # (N, F)
        for epoch in range(start, self.epochs):
            residual = phi @ weight - x                                                         # (N, O)
            weight = weight - self.lr * phi.T @ residual / len(q)
            loss = float(residual.pow(2).mean())
            if checkpoint is not None:
                torch.save({"weight": weight, "epoch": epoch}, checkpoint)
            self.epochs_run_.append(epoch)
            if on_epoch is not None:
                on_epoch(epoch, {"train_loss": loss, "val_rmse": loss ** 0.5})
            time.sleep(self.sleep_s)
            if epoch == self.fail_at:
                raise KeyboardInterrupt if self.fail_with == "interrupt" else Boom(f"injected failure at {epoch}")
        self.weight_ = weight
        return self

    def _features(self, q):
        return torch.cos(self.body.to_unit(q) @ self.omega_.to(q.dtype)) / N_FEATURES ** 0.5     # (B, F)

    def _predict(self, z):
        return (self._features(z) @ self.weight_.to(z.dtype)).reshape(-1, *self.output_shape)

    def _jacobian(self, z):
        u = self.body.to_unit(z)
        s = -torch.sin(u @ self.omega_.to(z.dtype)) / N_FEATURES ** 0.5                          # (B, F)
        d_phi = s[:, :, None] * self.omega_.T.to(z.dtype)[None] * self.body.unit_per_rad(z)      # (B, F, Dz)
        return torch.einsum("fo,bfd->bod", self.weight_.to(z.dtype), d_phi)

    def _precision(self, z):
        return torch.ones(z.shape[0], *self.output_shape, dtype=z.dtype)

    def _config(self):
        return {"epochs": self.epochs, "lr": self.lr}

    def _state(self):
        return {"omega": self.omega_, "weight": self.weight_}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        model = cls(body, modality, output_shape, **config)
        model.omega_, model.weight_ = state["omega"], state["weight"]
        return model


@dataclass(frozen=True)
class TinyConfig(ModelConfig):
    kind: ClassVar[str] = "tiny"
    epochs: int = 30  # gradient steps
    lr: float = 0.5  # step size


TINY = Kind("tiny", __name__, "TinyModel", "TinyModel", TinyConfig)   # `kinds.register(TINY)` makes it trainable


def tiny_config(data: Path, **changes) -> TrainConfig:
    """A TrainConfig for the tiny kind on `data` (ee_xyz, no progress bars); `changes` override TrainConfig fields
    and TinyConfig's hyper-parameters (epochs, lr) alike."""
    hyper = {f.name for f in dataclasses.fields(TinyConfig)}
    values = dict(data=data, modality="ee_xyz", progress=False)
    values.update({k: v for k, v in changes.items() if k not in hyper})
    return TrainConfig(model=TinyConfig(**{k: v for k, v in changes.items() if k in hyper}), **values)
