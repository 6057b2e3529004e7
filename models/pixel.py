"""Convolutional image decoder z → image as a SensoryModel (kind "pixel"), after Pixel-AIF.

Sancaktar, van Gerven & Lanillos 2020, "End-to-end pixel-based deep active inference for body perception
and action": fully connected layers, then transposed convolutions, sigmoid output. This decoder is laid out
for the AIF update, which needs forward + VJP for every trial every step: ×2 upsampling stages that halve
the channels as the resolution doubles (so little work at full resolution), ELU (C¹: smooth enough for
finite-difference checks and gradient descent), channels_last for oneDNN, and the exact image size by a
centre crop of the last stage (any H, W; C = 1 or more). The precision is one fixed number per pixel: a
hyper-parameter, or 1/σ² with σ² the mean squared residual on the validation set (train set without one).

The fit minimises `loss` per pixel (LOSSES): "cross_entropy" (read on the logits) or "mse" (through the sigmoid).
Both are minimised by the pixel's mean given the pose; they differ in the gradient a logit gets, σ − x against
2(σ − x)·σ(1 − σ). Where most of an image is black (a small arm in a frame of its whole reach), the squared error
pushes every logit far down in the first epochs, σ(1 − σ) vanishes there, and no pose is learned after: one dark
image for every pose (SO-101 at 64×64, README "Your own robot"). The cross-entropy's gradient does not vanish.

What the first layer reads of the pose (`inputs`, models/pose_inputs.py): by default learned products of the
joints' (1, cos q, sin q), the form in which a revolute chain places its links; "unit" reads the scaled angles u.

Two named capacities (`size`), each with its Adam step: "lean" (FC 64, channels 32/16/8, lr 4e-3 and wsd) and
"pixel_aif" (lr 2e-3; 5e-4 with the squared error, at 2e-3 a black image: see SIZES), the size of Pixel-AIF's
NAO decoder (FC 4→512→1120 = 16×7×10 at 56×80, transposed convolutions 16→64→16→C, each but the last
followed by a 3×3 convolution of the same width, which Pixel-AIF adds against checkerboard artifacts).
Unlike Pixel-AIF it keeps ELU for ReLU and has no dropout: the AIF update differentiates g, and a seed must
give one model. A third size, "splat", is not a conv stack: blobs placed by the joints' trig features
(models/splat.py), for arms seen small in a frame of their whole reach.
"""

from __future__ import annotations

import math
from contextlib import contextmanager

import torch
import torch.nn.functional as F
from torch import nn

from bodyschema.errors import must_be
from bodyschema.models import splat
from bodyschema.models._nn_fit import TrainSettings, build, check_fit_data, check_val, evaluate, train
from bodyschema.models._nn_model import NetModel
from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.pose_inputs import DEFAULT_INPUTS, ProductInputs, UnitInputs, check_inputs, pose_inputs
from bodyschema.models.scaling import BodySpec

ONEDNN_MIN_BATCH = 4   # latents per inference call from which oneDNN's convolutions pay: below, its per-call setup
# outweighs these small layers (one camera's frame; bench/conv_backend.py, 1 thread: at B = 1 predict 0.70×, the
# Jacobian 0.83×, forward + VJP 0.85× the time with it; from B = 4 the VJP, from B = 32 every call, is slower without)
SIZES = {   # name → capacity and its Adam step; an explicit fc_hidden / channels / refine / lr overrides the preset's
    "lean": {"fc_hidden": 64, "channels": (32, 16, 8), "refine": False, "lr": 4e-3, "schedule": "wsd"},  # 7×10×32 …
    # lean's step: 4e-3, held until the last 20 % of --epochs and then decayed (`_nn_fit.schedule_factor`). At 2e-3
    # (the default until 2026-11-30) the decoder was far from its fit at the recipes' end: on the same stores and
    # epochs the mean floor over the seen joints fell on all five stores measured (nao_arm 3 000 poses 2.3×, 18 000
    # poses 1.3× and L1 1.87° → 1.16°, Z1 1.4×, the UR5 1.7×, SO-101's first four joints 1.5×; README "Lean's
    # step"). The step is the cause: a constant 4e-3 did as well on nao_arm's short store, 2e-3 with wsd no better.
    # pixel_aif's mse_lr, its step under the squared error: at 2e-3 the first epoch's steps blow up its conv stack
    # (ELU outputs' mean 4, 8, 12 after the refines) and the last layer lands at -40 on every pixel: a black image,
    # σ' ≈ e⁻⁴⁰, and the squared error's gradient carries that σ' (nao_arm 64×64, 600 images: held-out MSE frozen at
    # 0.0317 from epoch 2, pose variation 0; at 56×80 too). The cross-entropy's does not: at 2e-3 it trains, 30 epochs
    # on the same images held-out MSE 0.0090 against 0.0155 at 5e-4 (bench/decoder_rule.py)
    "pixel_aif": {"fc_hidden": 512, "channels": (16, 64, 16), "refine": True, "lr": 2e-3, "mse_lr": 5e-4,
                  "schedule": "constant"},
    # not a conv stack: K blobs placed by the joints' trig features (models/splat.py); ≤ 7 joints. SO-101 URDF,
    # 3 000 images 128×128, 40 epochs: floors 2.5–12° per joint where lean's were 10.8–159° (README)
    "splat": {"points": 128, "lr": 3e-3, "schedule": "constant"},
}
# What a conv size's fit minimises unless told (LOSSES; splat's blobs have no logits: mse). Side by side (README
# "The loss"): nao_arm's long recipe L1 1.28° against mse's 1.67° (floors equal), SO-101 at 128×128 floors 6.9–119°
# against 10.8–159°, and at 64×64 a pose-dependent image where mse's fit went dark for every pose.
CONV_LOSS = "cross_entropy"


def image_layout(output_shape: tuple[int, ...]) -> tuple[int, int, int]:
    """(H, W) or (H, W, C) → (H, W, C); raises the house error otherwise."""
    if len(output_shape) not in (2, 3) or min(output_shape) < 1:
        raise ValueError(must_be("output_shape", "(H, W) for grayscale or (H, W, C) images", output_shape))
    h, w = output_shape[:2]
    return h, w, (output_shape[2] if len(output_shape) == 3 else 1)


class PixelDecoderNet(nn.Module):
    """u (B, Dz) in [-1, 1] → image (B, *output_shape) in (0, 1)."""

    def __init__(self, latent_dim: int, output_shape: tuple[int, ...], fc_hidden: int,
                 channels: tuple[int, ...], kernel: int = 4, refine: bool = False, inputs: nn.Module | None = None):
        super().__init__()
        self.inputs = UnitInputs(latent_dim) if inputs is None else inputs      # what the first layer reads of u
        self.output_shape = tuple(output_shape)
        self.h, self.w, c_out = image_layout(self.output_shape)
        scale = 2 ** len(channels)                                       # one ×2 stage per entry of `channels`
        self.h0, self.w0 = math.ceil(self.h / scale), math.ceil(self.w / scale)
        self.c0 = channels[0]
        self.fc = nn.Sequential(nn.Linear(self.inputs.size, fc_hidden), nn.ELU(),
                                nn.Linear(fc_hidden, self.c0 * self.h0 * self.w0), nn.ELU())
        stages = []
        for i, (a, b) in enumerate(zip(channels, (*channels[1:], c_out))):
            stages.append(nn.ConvTranspose2d(a, b, kernel, stride=2, padding=(kernel - 2) // 2))
            if i < len(channels) - 1:
                stages.append(nn.ELU())
                if refine:   # same-size 3×3 smoothing after an upsampling (Pixel-AIF's layout)
                    stages += [nn.Conv2d(b, b, 3, padding=1), nn.ELU()]
        self.up = nn.Sequential(*stages)

    def forward(self, u):
        return self.logits(u).sigmoid()

    def logits(self, u):
        """The image before its sigmoid: what the cross-entropy loss reads. u (B, Dz) → (B, *output_shape)"""
        y = self.fc(self.inputs(u)).reshape(-1, self.c0, self.h0, self.w0)   # (B, C0, h0, w0)
        y = self.up(y)                                                   # (B, C, h0·2^n, w0·2^n)
        top, left = (y.shape[2] - self.h) // 2, (y.shape[3] - self.w) // 2
        y = y[:, :, top:top + self.h, left:left + self.w]                # (B, C, H, W), centre crop
        y = y.permute(0, 2, 3, 1)                                        # (B, H, W, C): free in channels_last
        return y.reshape(-1, *self.output_shape)

    def forward_and_jacobian(self, u):
        """g(u) and ∂g/∂u by forward mode written out: the B primal rows and the B·Dz unit tangents go through
        each layer as one batch (a layer's linear part once on all rows, its bias on the primal rows only; an
        activation's derivative at the primal scales the tangents). Exact (autograd's JVPs, same float rounding)
        at the cost of one forward of batch B·(1 + Dz), ~6× cheaper than vmap(jacfwd), whose batching rules add
        a per-layer overhead that dwarfs these small convolutions (bench/tracking_jacobian.py).
        # u (B, Dz) → (B, *output_shape), (B, O, Dz)"""
        b, dz = u.shape
        phi, slopes = self.inputs.with_derivatives(u)                   # (B, P), (B, Dz, P)
        x = torch.cat([phi, slopes.transpose(0, 1).flatten(0, 1)])      # ((1+Dz)·B, P): row (1+j)·B + i is ∂φ_i/∂u_ij
        x = _with_tangents(self.fc, x, b).reshape(-1, self.c0, self.h0, self.w0)
        x = _with_tangents(self.up, x, b)                                # ((1+Dz)·B, C, H', W')
        top, left = (x.shape[2] - self.h) // 2, (x.shape[3] - self.w) // 2
        x = x[:, :, top:top + self.h, left:left + self.w]
        y = x[:b].sigmoid()                                              # (B, C, H, W)
        tangents = x[b:].unflatten(0, (dz, b)) * (y * (1 - y))          # (Dz, B, C, H, W): σ' = σ(1 − σ)
        jac = tangents.permute(1, 3, 4, 2, 0).reshape(b, -1, dz)         # (B, O, Dz), O in (H, W, C) order
        return y.permute(0, 2, 3, 1).reshape(-1, *self.output_shape), jac


def _with_tangents(layers: nn.Sequential, x: torch.Tensor, b: int) -> torch.Tensor:
    """Push the primal rows x[:b] and the tangent rows x[b:] through Linear / (transposed) convolution / ELU layers."""
    for layer in layers:
        if isinstance(layer, nn.ELU):
            primal = x[:b]
            act = F.elu(primal, layer.alpha)
            slope = torch.where(primal > 0, torch.ones_like(act), act + layer.alpha)   # ELU' = α eˣ = ELU + α
            x = torch.cat([act, (x[b:].unflatten(0, (-1, b)) * slope).flatten(0, 1)])
            continue
        if isinstance(layer, nn.Linear):
            x = F.linear(x, layer.weight)
        elif isinstance(layer, nn.ConvTranspose2d):
            x = F.conv_transpose2d(x, layer.weight, None, layer.stride, layer.padding, layer.output_padding,
                                   layer.groups, layer.dilation)
        elif isinstance(layer, nn.Conv2d):
            x = F.conv2d(x, layer.weight, None, layer.stride, layer.padding, layer.dilation, layer.groups)
        else:
            raise TypeError(must_be("layer", "Linear, Conv2d, ConvTranspose2d or ELU", type(layer).__name__))
        if layer.bias is not None:
            x[:b] += layer.bias.reshape(-1, *([1] * (x.ndim - 2)))     # the bias moves the primal only
    return x


@contextmanager
def convolutions_for(batch: int):
    """PyTorch's own convolutions for a batch below ONEDNN_MIN_BATCH latents, oneDNN (where the user left it on)
    from there: inference only, training's batches keep oneDNN and their float rounding."""
    before = torch.backends.mkldnn.enabled
    torch.backends.mkldnn.enabled = before and batch >= ONEDNN_MIN_BATCH
    try:
        yield
    finally:
        torch.backends.mkldnn.enabled = before


def fast_layout(net: nn.Module) -> nn.Module:
    """channels_last weights: oneDNN then runs the transposed convolutions in NHWC (≈2× faster on CPU)."""
    return net.to(memory_format=torch.channels_last)


@register_kind
class PixelDecoder(NetModel, BaseSensoryModel):
    kind = "pixel"
    exports_onnx = convolutional = True

    def __init__(self, body: BodySpec, modality: str, output_shape: tuple[int, ...], *,   # the data's (H, W[, C])
                 size: str = "lean",                        # a capacity preset of SIZES
                 fc_hidden: int | None = None,              # None: the preset's
                 channels: tuple[int, ...] | None = None,   # one ×2 upsampling per entry; None: the preset's
                 refine: bool | None = None,                # 3×3 conv after each upsampling; None: the preset's
                 loss: str | None = None,                   # what the fit minimises (LOSSES); None: CONV_LOSS
                 precision: float | None = None,            # None: 1/σ² from the validation residuals
                 epochs: int = 100, batch_size: int = 64, lr: float | None = None, patience: int = 10,
                 weight_decay: float = 0.0, lr_schedule: str | None = None,   # None: the preset's
                 inputs: str = DEFAULT_INPUTS):             # what the conv sizes read of the pose (pose_inputs.py)
        super().__init__(body, modality, output_shape)
        image_layout(self.output_shape)
        if size not in SIZES:
            raise ValueError(must_be("size", f"one of {sorted(SIZES)}", size))
        preset = {**SIZES["lean"], **SIZES[size]}                # splat: the conv fields unused, kept valid
        if size == "splat" and not splat.fits(self.latent_dim):
            raise ValueError(must_be("size 'splat'", "used on at most 7 joints (3^D trig features per blob)",
                                     self.latent_dim, "Use size 'lean' or 'pixel_aif'."))
        fc_hidden = preset["fc_hidden"] if fc_hidden is None else fc_hidden
        channels = preset["channels"] if channels is None else tuple(channels)
        if not channels or min(channels) < 1 or fc_hidden < 1:
            raise ValueError(must_be("channels and fc_hidden", "a non-empty tuple of positive ints and > 0",
                                     (channels, fc_hidden)))
        if precision is not None and not precision > 0:
            raise ValueError(must_be("precision", "> 0 or None (fitted)", precision))
        self.size, self.fc_hidden, self.channels, self.fixed_precision = size, fc_hidden, tuple(channels), precision
        self.refine = bool(preset["refine"] if refine is None else refine)
        check_inputs(inputs, self.latent_dim)
        self.inputs = inputs
        self.loss = ("mse" if size == "splat" else CONV_LOSS) if loss is None else loss
        if self.loss not in LOSSES:
            raise ValueError(must_be("loss", f"one of {sorted(LOSSES)}", self.loss))
        if size == "splat" and self.loss != "mse":
            raise ValueError(must_be("loss", "'mse' for size 'splat'", self.loss,
                                     "A sum of blobs has no logits to read the cross-entropy on."))
        if lr is None:                                           # the preset's, for its loss
            lr = preset.get("mse_lr", preset["lr"]) if self.loss == "mse" else preset["lr"]
        lr_schedule = preset["schedule"] if lr_schedule is None else lr_schedule
        self.settings = TrainSettings(epochs, batch_size, lr, patience, weight_decay, lr_schedule)
        self.precision_: float | None = None
        self.fit_info_: dict = {}

    # ---- fit ------------------------------------------------------------------------------------------
    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch=None, progress: bool = False, checkpoint=None,
            device: str = "cpu", mixed_precision: bool = False):
        """Train on q (N, Dz) rad, x (N, *output_shape) by the per-pixel `loss` (`_nn_fit.train`) on
        `device`; self (its network on the CPU: `to(device)` for inference elsewhere)."""
        q, x = check_fit_data(q, x, self.latent_dim, self.output_shape)     # (N, Dz), (N, *out) in [0, 1]
        val = check_val(val, self.latent_dim, self.output_shape)
        gen = torch.Generator().manual_seed(seed)
        net = self.new_net(gen, x)
        to_unit = self.body.to_unit
        self.fit_info_ = train(net, LOSSES[self.loss], (to_unit(q), x), self.settings, gen,
                               val=(to_unit(val[0]), val[1]) if val is not None else None,
                               on_epoch=on_epoch, progress=progress, checkpoint=checkpoint, desc="fit pixel",
                               device=device, mixed_precision=mixed_precision)
        q_res, x_res = val if val is not None else (q, x)
        self.residual_var_ = evaluate(net, _mse, (to_unit(q_res), x_res), self.settings.batch_size)   # on CPU
        self.precision_ = self.fixed_precision or 1.0 / max(self.residual_var_, 1e-8)
        self._set_net(net)
        return self

    def new_net(self, gen: torch.Generator, x: torch.Tensor | None = None) -> PixelDecoderNet | splat.SplatNet:
        """The network before training, every weight drawn from `gen` (splat's start from the images x)."""
        net = fast_layout(build(self._factory, gen))
        if self.size == "splat":
            net.start_from(x, gen)
        elif isinstance(net.inputs, ProductInputs):
            net.inputs.start(gen)
        return net

    def _factory(self) -> PixelDecoderNet | splat.SplatNet:
        if self.size == "splat":
            return splat.SplatNet(self.body, self.output_shape, SIZES["splat"]["points"],
                                  image_layout(self.output_shape)[2])
        return PixelDecoderNet(self.latent_dim, self.output_shape, self.fc_hidden, self.channels, refine=self.refine,
                               inputs=pose_inputs(self.inputs, self.body))

    # ---- hooks ----------------------------------------------------------------------------------------
    def _outputs(self, net, u):
        return net(u)

    def _g(self, z, net=None):
        with convolutions_for(len(z)):          # a call's backend, outside `_outputs`: the ONNX graph stays generic
            return super()._g(z, net)

    def _jacobian(self, z):
        return self._predict_and_jacobian(z)[1]

    def predict_and_jacobian(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """g(z) and its Jacobian from one pass: a Gauss–Newton step needs both. # (B, Dz) → (B, *out), (B, O, Dz)"""
        return self._predict_and_jacobian(self._check_z(z))

    def _predict_and_jacobian(self, z):
        net, z_dev = self._net(z.dtype), z.to(self.device)
        with torch.no_grad(), convolutions_for(len(z_dev)):
            y, jac = net.forward_and_jacobian(self.body.to_unit(z_dev))
        return y.to(z.device), (jac * self.body.unit_per_rad(z_dev)).to(z.device)   # chain rule through to_unit

    def _precision(self, z):
        return torch.full((z.shape[0], *self.output_shape), self.precision_, dtype=z.dtype, device=z.device)

    def _config(self):
        return {"size": self.size, "fc_hidden": self.fc_hidden, "channels": list(self.channels),
                "refine": self.refine, "loss": self.loss, "precision": self.fixed_precision,
                "epochs": self.settings.epochs, "batch_size": self.settings.batch_size, "lr": self.settings.lr,
                "patience": self.settings.patience, "weight_decay": self.settings.weight_decay,
                "lr_schedule": self.settings.lr_schedule, "inputs": self.inputs}

    def _state(self):
        return {**super()._state(), "precision": torch.tensor(self.precision_, dtype=torch.float64)}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        # saved before `loss` existed: the fit was by squared error (only a fit reads it); before `inputs`: u read
        model = cls(body, modality, output_shape,
                    **{"loss": "mse", "inputs": "unit", **config, "channels": tuple(config["channels"])})
        model.precision_ = float(state["precision"])
        model._restore_net(lambda: fast_layout(model._factory()), state)
        return model


def _mse(net: nn.Module, u: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Mean squared error per pixel. u (B, Dz), x (B, *out)."""
    return (net(u) - x).pow(2).mean()


def _cross_entropy(net: PixelDecoderNet, u: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy per pixel, x in [0, 1] as soft labels, read on the logits. u (B, Dz), x (B, *out)."""
    return F.binary_cross_entropy_with_logits(net.logits(u), x)


LOSSES = {"mse": _mse, "cross_entropy": _cross_entropy}
