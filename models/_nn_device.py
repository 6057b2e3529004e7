"""How the network training loop uses its device: the batch and learning-rate rule on a GPU, and bf16.

On the CPU the plan is the identity: the settings as given, float32, no learning-rate writes, so a seed gives the
same model as before the rule. On cuda (issue 36, measured on one H100 with nao_arm's lean decoder: 2.06 s per
epoch at batch 64, 0.11 s at 512, where the per-step launch overhead, not the arithmetic, set the time):
- batch size: at least GPU_MIN_BATCH (a larger one given is kept);
- learning rate × √(new batch / given batch), the square-root rule for Adam (Malladi et al. 2022, "On the SDEs and
  scaling rules for adaptive gradient algorithms"; the linear rule of SGD overshoots with Adam), reached by a
  linear warm-up over the first epoch's steps (Goyal et al. 2017);
- (the convolutional networks are channels-last on every device already: `pixel.fast_layout`);
- bf16 autocast of the forward pass only when asked (`mixed_precision`): the loss and the optimizer stay float32.
  Whether bf16 keeps the CPU recipe's held-out error was not measured (no GPU was lent): off by default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

GPU_MIN_BATCH = 512


@dataclass(frozen=True)
class DevicePlan:
    batch_size: int
    lr_scale: float                   # the learning rate's factor once warmed up
    warmup_epochs: int                # linear warm-up from lr_scale / steps to lr_scale over these epochs' steps
    autocast: torch.dtype | None      # the forward pass's dtype under autocast; None: float32 throughout

    def describe(self, batch_size: int, lr: float) -> str:
        """One line for the log: what the plan changed."""
        parts = []
        if self.batch_size != batch_size:
            parts.append(f"batch {batch_size} → {self.batch_size}, lr {lr:.3g} → {lr * self.lr_scale:.3g} "
                         f"(√{self.batch_size / batch_size:g}) after a {self.warmup_epochs}-epoch warm-up")
        if self.autocast is not None:
            parts.append(f"{str(self.autocast).removeprefix('torch.')} autocast")
        return ", ".join(parts) or "as given"


def plan_for(device: torch.device, batch_size: int, mixed_precision: bool = False) -> DevicePlan:
    """The plan of a fit on `device` with the given batch size."""
    autocast = torch.bfloat16 if mixed_precision else None
    if device.type != "cuda":
        return DevicePlan(batch_size, 1.0, 0, autocast)
    batch = max(batch_size, GPU_MIN_BATCH)
    return DevicePlan(batch, math.sqrt(batch / batch_size), 1 if batch > batch_size else 0, autocast)


def warmup_factor(plan: DevicePlan, step: int, steps_per_epoch: int) -> float:
    """The learning rate's factor at optimizer step `step` (0-based, counted over the whole fit)."""
    warmup_steps = plan.warmup_epochs * steps_per_epoch
    if warmup_steps == 0 or step >= warmup_steps:
        return plan.lr_scale
    return plan.lr_scale * (step + 1) / warmup_steps
