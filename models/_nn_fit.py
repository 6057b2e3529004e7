"""Fitting the neural-network models (MDN, pixel decoder, multimodal members, image encoder).

- `check_fit_data`: validate and convert (q, x) at the `fit` edge (numpy or torch; uint8 images → [0, 1]).
- `build`: construct a module without touching the global RNG and initialise it from a `torch.Generator`.
- `train`: the one minibatch loop (seeded shuffling, Adam, early stopping on the validation loss keeping the
  best weights, a checkpoint written every epoch from which a killed run resumes bit-for-bit; a tqdm bar when
  asked, `progress=True`: the CLI asks, a library call prints nothing by default).

The trained network as a model (`NetHolder`, `NetModel`): `_nn_model.py`.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from bodyschema.errors import must_be
from bodyschema.models._nn_device import DevicePlan, plan_for, warmup_factor
from bodyschema.models.device import check_device
from bodyschema.models.files import torch_bytes, write_atomically
from bodyschema.models.scaling import IMAGE_SCALE

_INIT_LAYERS = (nn.Linear, nn.Conv2d, nn.ConvTranspose2d)
_log = logging.getLogger(__name__)


# ---- data at the fit edge ---------------------------------------------------------------------------
def check_fit_data(q, x, latent_dim: int, output_shape: tuple[int, ...], name: str = "x", q_name: str = "q"
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """(N, Dz) rad and (N, *output_shape) → float32 tensors; uint8 x is divided by 255. Raises the house errors."""
    q, x = _as_tensor(q_name, q), _as_tensor(name, x)
    is_uint8 = x.dtype == torch.uint8
    q, x = _finite_float(q_name, q), _finite_float(name, x)
    if is_uint8:
        x = x / IMAGE_SCALE
    if q.ndim != 2 or q.shape[1] != latent_dim:
        raise ValueError(must_be(q_name, f"of shape (N, {latent_dim}) joint angles in rad", tuple(q.shape)))
    if tuple(x.shape[1:]) != tuple(output_shape) or x.ndim != len(output_shape) + 1:
        raise ValueError(must_be(name, f"of shape (N, {', '.join(map(str, output_shape))})", tuple(x.shape),
                                 "The model's output_shape must match the data."))
    if x.shape[0] != q.shape[0]:
        raise ValueError(must_be(f"len({name})", f"equal to len({q_name}) = {q.shape[0]} (one row per pose)",
                                 x.shape[0]))
    if q.shape[0] < 2:
        raise ValueError(must_be(f"len({q_name})", "at least 2 samples", q.shape[0]))
    return q, x


def check_val(val, latent_dim: int, output_shape: tuple[int, ...]) -> tuple[torch.Tensor, torch.Tensor] | None:
    """`val` = (q_val, x_val) or None, checked as the training data."""
    if val is None:
        return None
    if not isinstance(val, (tuple, list)) or len(val) != 2:
        raise TypeError(must_be("val", "a pair (q_val, x_val) or None", type(val).__name__))
    return check_fit_data(val[0], val[1], latent_dim, output_shape, name="x_val", q_name="q_val")


def output_standardizer(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-output mean and scale (std; 1 where an output is constant, e.g. z of a planar arm). # (O,), (O,)"""
    flat = x.reshape(x.shape[0], -1)   # (N, O)
    std = flat.std(0)
    return flat.mean(0), torch.where(std > 1e-8, std, torch.ones_like(std))


def _as_tensor(name: str, a) -> torch.Tensor:
    """torch, numpy or any array-like (zarr, lists) → a tensor of its own dtype."""
    if isinstance(a, torch.Tensor):
        return a.detach()
    arr = np.asarray(a)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(must_be(name, "a numeric numpy array or torch.Tensor", f"{type(a).__name__} of {arr.dtype}"))
    return torch.from_numpy(np.ascontiguousarray(arr))


def _finite_float(name: str, a: torch.Tensor) -> torch.Tensor:
    if a.is_complex():
        raise TypeError(must_be(f"{name}.dtype", "a real (float or uint8) type", a.dtype))
    a = a.to(torch.float32)
    if not torch.isfinite(a).all():
        bad = int((~torch.isfinite(a)).reshape(a.shape[0], -1).any(1).sum()) if a.ndim else 1
        raise ValueError(must_be(name, "finite", f"{bad} rows with NaN or inf", "Drop or repair those samples."))
    return a.contiguous()


# ---- seeded construction ----------------------------------------------------------------------------
def build(factory: Callable[[], nn.Module], gen: torch.Generator) -> nn.Module:
    """Build on the meta device (no global RNG draw), then initialise every layer from `gen`."""
    with torch.device("meta"):
        module = factory()
    module = module.to_empty(device="cpu")
    for layer in module.modules():
        if isinstance(layer, _INIT_LAYERS):   # PyTorch's default init, drawn from `gen`
            nn.init.kaiming_uniform_(layer.weight, a=math.sqrt(5), generator=gen)
            if layer.bias is not None:
                fan_in, _ = nn.init._calculate_fan_in_and_fan_out(layer.weight)
                bound = 1.0 / math.sqrt(fan_in) if fan_in > 0 else 0.0
                nn.init.uniform_(layer.bias, -bound, bound, generator=gen)
        elif isinstance(layer, LeafParams):
            for p in layer.parameters(recurse=False):
                nn.init.zeros_(p)
        elif any(True for _ in layer.parameters(recurse=False)):
            raise TypeError(must_be("layer", f"one of {[c.__name__ for c in _INIT_LAYERS]}", type(layer).__name__))
    return module


class LeafParams(nn.Module):
    """Free parameters (e.g. log-precisions) that the owner initialises itself after `build`."""

    def __init__(self, **shapes: tuple[int, ...]):
        super().__init__()
        for name, shape in shapes.items():
            self.register_parameter(name, nn.Parameter(torch.zeros(shape)))


# ---- the training loop ------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrainSettings:
    epochs: int = 200
    batch_size: int = 128
    lr: float = 1e-3
    patience: int = 20            # epochs without improvement of the validation (else train) loss
    weight_decay: float = 0.0
    lr_schedule: str = "constant"  # one of LR_SCHEDULES: the step's factor over the fit (`schedule_factor`)

    def __post_init__(self):
        if min(self.epochs, self.batch_size, self.patience) < 1 or not self.lr > 0 or self.weight_decay < 0:
            raise ValueError(must_be("(epochs, batch_size, patience, lr, weight_decay)",
                                     "(≥ 1, ≥ 1, ≥ 1, > 0, ≥ 0)",
                                     (self.epochs, self.batch_size, self.patience, self.lr, self.weight_decay)))
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(must_be("lr_schedule", f"one of {list(LR_SCHEDULES)}", self.lr_schedule))


# "cosine": lr · ½(1 + cos(π t/T)) over the T steps of `epochs` (the cap), from the full step to none (Loshchilov &
# Hutter 2017, without restarts). "wsd" (warm-up-stable-decay without the warm-up; Hu et al. 2024, MiniCPM): the full
# step until the last WSD_DECAY share of the steps, then the same half cosine down to none over them.
LR_SCHEDULES = ("constant", "cosine", "wsd")
WSD_DECAY = 0.2


def schedule_factor(schedule: str, step: int, total_steps: int) -> float:
    """The learning rate's factor at optimizer step `step` (0-based) of a fit capped at `total_steps`."""
    if schedule == "constant":
        return 1.0
    decay_start = 0 if schedule == "cosine" else (1 - WSD_DECAY) * total_steps
    done = min(max(step - decay_start, 0) / (total_steps - decay_start), 1.0)
    return 0.5 * (1.0 + math.cos(math.pi * done))


def train(module: nn.Module, loss_fn: Callable[..., torch.Tensor], data: tuple[torch.Tensor, ...],
          settings: TrainSettings, gen: torch.Generator, *, val: tuple[torch.Tensor, ...] | None = None,
          on_epoch: Callable[[int, dict], None] | None = None, progress: bool = False,
          checkpoint: str | Path | None = None, param_groups: list[dict] | None = None,
          desc: str = "fit", device: str | torch.device = "cpu", mixed_precision: bool = False,
          plan: DevicePlan | None = None) -> dict[str, float]:
    """Minimise `loss_fn(module, *batch)` (a mean over the batch); leaves the best weights in `module`.

    The score is the validation loss when `val` is given, else the train loss. `settings.epochs` is a cap: the
    loop stops once the score has not improved for `settings.patience` epochs, restores the best epoch's weights
    and says so in one INFO line (which epoch, of how many, and whether the cap or the patience ended it). An epoch
    whose training loss is NaN or inf stops it at once (a WARNING; `diverged_epoch` in the result), its weights
    and checkpoint those of the last finite epoch.
    `checkpoint` is rewritten atomically after every epoch (before `on_epoch`), and resumed from when it exists
    at the start.
    The module and the data live on `device` while training; the module is back on the CPU on return
    (models are saved and shipped on CPU; `NetModel.to` moves them for inference). The shuffling stays on
    the CPU generator, so a seed gives the same minibatches on every device. `plan` (None: the device's,
    `_nn_device.plan_for`) sets the batch size, the learning rate's scale and warm-up, and bf16 autocast
    (`mixed_precision`); on the CPU it changes nothing. The epoch's loss is summed on the device and read once per
    epoch (no host synchronisation per step).
    """
    device = check_device(device)
    plan = plan or plan_for(device, settings.batch_size, mixed_precision)
    module.to(device)
    data = tuple(d.to(device) for d in data)
    val = tuple(d.to(device) for d in val) if val is not None else None
    n = data[0].shape[0]
    opt = torch.optim.Adam(param_groups or module.parameters(), lr=settings.lr, weight_decay=settings.weight_decay)
    base_lrs = [group["lr"] for group in opt.param_groups]     # before a resume restores a warmed-up one
    steps_per_epoch = math.ceil(n / plan.batch_size)
    if plan != plan_for(torch.device("cpu"), settings.batch_size):
        _log.info("%s on %s: %s", desc, device, plan.describe(settings.batch_size, settings.lr))
    fingerprint = {"n": n, "shapes": [list(d.shape[1:]) for d in data], **asdict(settings)}
    state = {"epoch": -1, "best": math.inf, "best_epoch": -1, "bad": 0,
             "best_weights": _clone(module.state_dict()), "metrics": {}}
    if checkpoint is not None and Path(checkpoint).is_file():
        state = _resume(Path(checkpoint), module, opt, gen, fingerprint, device)
    first, began, diverged = state["epoch"] + 1, time.perf_counter(), None
    score_name = "validation" if val is not None else "train"
    bar = tqdm(total=settings.epochs, initial=first, desc=desc, disable=not progress, leave=False)
    for epoch in range(state["epoch"] + 1, settings.epochs):
        if state["bad"] >= settings.patience:
            break
        start = time.perf_counter()
        module.train()
        perm = torch.randperm(n, generator=gen)
        total = torch.zeros((), dtype=torch.float64, device=device)
        for step, i in enumerate(range(0, n, plan.batch_size), start=epoch * steps_per_epoch):
            if plan.lr_scale != 1.0 or settings.lr_schedule != "constant":
                factor = warmup_factor(plan, step, steps_per_epoch) * schedule_factor(
                    settings.lr_schedule, step, settings.epochs * steps_per_epoch)
                for group, lr in zip(opt.param_groups, base_lrs):
                    group["lr"] = lr * factor
            idx = perm[i:i + plan.batch_size]
            with _autocast(device, plan.autocast):
                loss = loss_fn(module, *(d[idx] for d in data))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += loss.detach().double() * len(idx)   # float64 as the former Python float sum: the same bits
        metrics = {"train_loss": float(total) / n}
        if not math.isfinite(metrics["train_loss"]):    # the weights are NaN/inf now: no later epoch recovers
            diverged = epoch
            break
        if val is not None:
            metrics["val_loss"] = evaluate(module, loss_fn, val, plan.batch_size)
        score = metrics.get("val_loss", metrics["train_loss"])
        if score < state["best"]:
            state.update(best=score, best_epoch=epoch, bad=0, best_weights=_clone(module.state_dict()))
        else:
            state["bad"] += 1
        metrics.update(best_loss=state["best"], epoch_seconds=time.perf_counter() - start)
        state.update(epoch=epoch, metrics=metrics)
        if checkpoint is not None:
            _save_checkpoint(Path(checkpoint), state, module, opt, gen, fingerprint)
        bar.update(1)
        # refresh=False: the next draw shows it; a forced draw each epoch ignored a log file's 30 s (bodyschema.log)
        bar.set_postfix({k: f"{v:.4g}" for k, v in metrics.items() if k.endswith("loss")}, refresh=False)
        if on_epoch is not None:
            on_epoch(epoch, dict(metrics))
    bar.close()
    _log.debug("%s: epochs %d–%d on %d rows (%s) in %.2f s; best epoch %d", desc, first, state["epoch"], n, device,
               time.perf_counter() - began, state["best_epoch"])
    stopped = state["epoch"] + 1 < settings.epochs   # early: `patience` epochs without a better score, or diverged
    if diverged is not None:
        _log.warning("%s: the training loss became NaN or inf in epoch %d (a smaller --lr may help); stopped there "
                     "and kept epoch %d's weights (%s loss %.4g)", desc, diverged + 1, state["best_epoch"] + 1,
                     score_name, state["best"])
    else:
        _log.info("%s: %s; kept epoch %d's weights (%s loss %.4g)", desc, _ending(state, settings, stopped, score_name),
                  state["best_epoch"] + 1, score_name, state["best"])
    module.load_state_dict(state["best_weights"])
    module.eval().to("cpu")
    return {"best_loss": state["best"], "best_epoch": state["best_epoch"], "epochs_run": state["epoch"] + 1,
            "stopped_early": stopped, "diverged_epoch": diverged}


def _ending(state: dict, settings: TrainSettings, stopped: bool, score_name: str) -> str:
    """How the fit ended, in words: stopped early, or ran to the cap still improving (then more epochs may help)."""
    if stopped:
        return (f"stopped after {state['epoch'] + 1} of at most {settings.epochs} epochs, the {score_name} loss not "
                f"better for {settings.patience}")
    if state["bad"] == 0:
        return f"ran all {settings.epochs} epochs (the cap), the last one the best: more --epochs may lower the loss"
    return (f"ran all {settings.epochs} epochs (the cap), the {score_name} loss last better {state['bad']} epochs "
            f"before the end")


@torch.no_grad()
def evaluate(module: nn.Module, loss_fn, data: tuple[torch.Tensor, ...], batch_size: int) -> float:
    """The mean loss over `data` in float32 (no autocast), summed on its device, read once."""
    was_training = module.training
    module.eval()
    n = data[0].shape[0]
    total = torch.zeros((), dtype=torch.float64, device=data[0].device)
    for i in range(0, n, batch_size):
        total += loss_fn(module, *(d[i:i + batch_size] for d in data)).double() * min(batch_size, n - i)
    module.train(was_training)
    return float(total) / n


def _autocast(device: torch.device, dtype: torch.dtype | None):
    """bf16 autocast of the forward pass when the plan asks; else no context at all (float32 as before)."""
    return torch.autocast(device.type, dtype=dtype) if dtype is not None else contextlib.nullcontext()


def _clone(weights: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in weights.items()}


def _save_checkpoint(path: Path, state: dict, module, opt, gen, fingerprint) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    # Atomic: a kill or a full disk mid-write leaves the previous checkpoint intact and no temporary behind.
    write_atomically({path: torch_bytes({**state, "weights": module.state_dict(), "optimizer": opt.state_dict(),
                                         "rng": gen.get_state(), "fingerprint": fingerprint})})


def _resume(path: Path, module, opt, gen, fingerprint, device: torch.device) -> dict:
    saved = torch.load(path, weights_only=True, map_location=device)   # a checkpoint resumes on any device
    if saved.get("fingerprint") != fingerprint:
        raise ValueError(must_be("checkpoint", f"from a run with the same data and settings {fingerprint}",
                                 saved.get("fingerprint"), f"Delete {str(path)!r} or pass another checkpoint path."))
    module.load_state_dict(saved["weights"])
    opt.load_state_dict(saved["optimizer"])
    gen.set_state(saved["rng"].cpu())
    return {k: saved[k] for k in ("epoch", "best", "best_epoch", "bad", "best_weights", "metrics")}
