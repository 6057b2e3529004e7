"""Training data of the GP models: validation at the `fit` edge, random subsets, target standardization.

`fit(q, x)` takes joint angles q (N, Dz) in rad and observations x (N, *output_shape), as numpy arrays or
torch tensors; everything is turned into float64 tensors here and checked once, with the house error messages.
"""

from __future__ import annotations

import numpy as np
import torch

from bodyschema.errors import must_be
from bodyschema.models.scaling import BodySpec

STD_FLOOR = 1e-12   # output units; a constant output (e.g. z of a planar arm) is standardized with std 1


def as_float64(name: str, value) -> torch.Tensor:
    """numpy array or torch tensor of numbers → float64 tensor (a copy), else TypeError."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        value = torch.from_numpy(value)
    if not isinstance(value, torch.Tensor) or value.dtype.is_complex or value.dtype == torch.bool:
        got = f"{type(value).__name__} of {value.dtype}" if hasattr(value, "dtype") else type(value).__name__
        raise TypeError(must_be(name, "a numpy array or torch.Tensor of real numbers", got))
    return value.detach().to(torch.float64).clone()


def check_training_data(q, x, body: BodySpec, output_shape: tuple[int, ...], prefix: str = "") -> tuple[
        torch.Tensor, torch.Tensor]:
    """Validate and convert a (q, x) pair. → q (N, Dz) rad, x (N, O) flattened outputs, both float64."""
    q, x = as_float64(f"{prefix}q", q), as_float64(f"{prefix}x", x)
    dz = body.latent_dim
    if q.ndim != 2 or q.shape[1] != dz:
        raise ValueError(must_be(f"{prefix}q", f"of shape (N, {dz}) for joints {list(body.joint_names)}",
                                 tuple(q.shape), "Pass one row of joint angles (rad) per sample."))
    if tuple(x.shape[1:]) != tuple(output_shape) or x.ndim < 1:
        raise ValueError(must_be(f"{prefix}x", f"of shape (N, {', '.join(map(str, output_shape))})", tuple(x.shape),
                                 "x must match the model's output_shape."))
    if x.shape[0] != q.shape[0]:
        raise ValueError(must_be(f"{prefix}q and {prefix}x", "of the same length (one x per q)",
                                 (q.shape[0], x.shape[0]), "Check that both come from the same dataset rows."))
    if q.shape[0] < 2:
        raise ValueError(must_be(f"{prefix}q", "at least 2 samples", q.shape[0]))
    for name, t in ((f"{prefix}q", q), (f"{prefix}x", x)):
        if not torch.isfinite(t).all():
            bad = int((~torch.isfinite(t)).reshape(t.shape[0], -1).any(-1).sum())
            raise ValueError(must_be(name, "finite", f"{bad} rows with NaN or inf",
                                     "Drop or repair those samples before fitting."))
    return q, x.reshape(x.shape[0], -1)


def training_data(model, q, x, val, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, tuple | None,
                                                     torch.Generator]:
    """A GP's training data checked: all of it (q (N, Dz) rad, y (N, O)), the indices of its seeded random subset of
    at most `model.max_points` (n,), the checked `val` pair (or None), and the generator the hyper-parameter subset
    is drawn with next."""
    q, y = check_training_data(q, x, model.body, model.output_shape)            # (N, Dz), (N, O)
    if val is not None:
        val = check_training_data(*val, model.body, model.output_shape, prefix="val ")
    gen = torch.Generator().manual_seed(int(seed))
    return q, y, random_subset(q.shape[0], model.max_points, gen), val, gen


def training_subset(model, q, x, val, seed: int) -> tuple[torch.Tensor, torch.Tensor, tuple | None,
                                                         torch.Generator]:
    """`training_data`'s subset only: (u (n, Dz) in the unit box, y (n, O)), `val` and the generator."""
    q, y, keep, val, gen = training_data(model, q, x, val, seed)
    return model.body.to_unit(q[keep]), y[keep], val, gen


def random_subset(n: int, size: int, gen: torch.Generator) -> torch.Tensor:
    """Indices of a uniform random subset of `size` out of `n` (all of them, in order, when size ≥ n). # (m,)"""
    if size >= n:
        return torch.arange(n)
    return torch.randperm(n, generator=gen)[:size].sort().values


def standardize(y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-output mean and std. y (N, O) → standardized (O, N), mean (O,), std (O,) in output units."""
    mean = y.mean(0)                                                        # (O,)
    std = y.std(0, correction=0)                                            # (O,)
    std = torch.where(std > STD_FLOOR, std, torch.ones_like(std))
    return ((y - mean) / std).T.contiguous(), mean, std


def restore_state(model, state: dict[str, torch.Tensor], keys: tuple[str, ...]) -> None:
    """Set the fitted `<key>_` attributes (float64) of a GP model from its saved tensors."""
    missing = [key for key in keys if key not in state]
    if missing:
        raise ValueError(must_be("state.pt", f"a {model.kind} state with tensors {list(keys)}", f"missing {missing}",
                                 "The saved model is incomplete: save it again."))
    for key in keys:
        setattr(model, f"{key}_", state[key].to(torch.float64))


class SavedGPState:
    """Save/load of a GP kind's fitted `<key>_` tensors, the class's STATE_KEYS (mixed in before BaseSensoryModel)."""

    STATE_KEYS: tuple[str, ...] = ()

    def _state(self):
        return {key: getattr(self, f"{key}_") for key in self.STATE_KEYS}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        model = cls(body, modality, output_shape, **config)
        restore_state(model, state, cls.STATE_KEYS)
        model._restored()
        return model

    def _restored(self) -> None:
        """After the saved tensors are set (a kind that caches a solve from them redoes it here)."""


def check_gp_hyper(hyper_points, max_points, noise_floor) -> None:
    """The hyper-parameters both GP kinds share: subset sizes ≥ 2 and a positive noise floor."""
    for name, value in (("hyper_points", hyper_points), ("max_points", max_points)):
        if int(value) < 2:
            raise ValueError(must_be(name, "an integer ≥ 2", value))
    if not noise_floor > 0:
        raise ValueError(must_be("noise_floor", "> 0 (standardized target units)", noise_floor))
