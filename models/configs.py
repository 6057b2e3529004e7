"""One frozen config dataclass per trainable model kind: its hyper-parameters, with the model's own defaults.

A config's fields are exactly the keyword arguments of the kind's constructor (after body, modality and shape),
with the same defaults; `tests/models/test_configs.py` compares them with the signatures, so neither can drift.
The comment after each field is its help line in `bodyschema train <kind> --help` (tyro reads it).
This module imports no model code (no torch, gpytorch or sklearn): the CLI builds its help from it cheaply.
`ModelConfig.__post_init__` checks the values by their annotations (a finite number ≥ 0 where a float goes,
an integer ≥ 0 where an int goes, ≥ 1 for the COUNTS every fit refuses at 0, a listed word where a Literal goes);
the model refines the bounds it needs.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass
from typing import ClassVar, Literal

from bodyschema.errors import must_be

# Integer hyper-parameters that a fit refuses at 0 (the minibatch loop's TrainSettings, the MDN's mixture): refused
# here already, when the command is parsed, not after the dataset has been loaded.
COUNTS = ("epochs", "batch_size", "patience", "n_components", "pool")


@dataclass(frozen=True)
class ModelConfig:
    """Base of the per-kind configs: `kind` names the model kind (models/kinds.py) the config trains."""

    kind: ClassVar[str] = ""
    # Constructor keywords a config leaves out on purpose (each with its reason in the subclass).
    not_on_cli: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self) -> None:
        hints = typing.get_type_hints(type(self))
        problems = [must_be(f"--{f.name.replace('_', '-')}", _expected(f.name, hints[f.name]), getattr(self, f.name))
                    for f in dataclasses.fields(self) if not _accepts(f.name, getattr(self, f.name), hints[f.name])]
        if problems:
            raise ValueError("\n".join(problems))

    def to_kwargs(self) -> dict[str, typing.Any]:
        """The constructor keywords: field name → value (tuples stay tuples, dicts are copied)."""
        return {f.name: _copy(getattr(self, f.name)) for f in dataclasses.fields(self)}


@dataclass(frozen=True)
class GPRConfig(ModelConfig):
    kind: ClassVar[str] = "gpr"
    hyper_points: int = 500  # the marginal likelihood is fitted on this many samples: O(m³) per step
    max_points: int = 5000  # RBF: conditioned on at most this many samples (O(n³), O(n²) memory); kinematic: on all
    adam_steps: int = 0  # optional Adam steps between the coarse and the fine L-BFGS-B runs (not needed)
    lbfgs_steps: int = 200  # at most this many evaluations per L-BFGS-B run (each output, coarse and fine)
    lr: float = 0.05  # Adam step on the log kernel hyper-parameters
    noise_floor: float = 3e-8  # noise variance floor on standardized targets: sets the error on noise-free data
    kernel: Literal["auto", "rbf", "kinematic"] = "auto"  # auto: the likelier; kinematic: exact on ≤ 7 revolute joints


@dataclass(frozen=True)
class SVGPConfig(ModelConfig):
    kind: ClassVar[str] = "svgp"
    num_inducing: int = 1000  # inducing points per output: O(M²) memory, O(N·M²) time for the closed-form q(u)
    inducing_init: Literal["kmeans", "random"] = "kmeans"  # inducing points start at k-means centres or a random subset
    hyper_points: int = 2000  # starting kernel: exact marginal likelihood on this many samples (500: 2x the error)
    elbo_epochs: int = 0  # minibatch ELBO passes over the data (0: none; the starting kernel and inducing points)
    batch_size: int = 1024  # samples per minibatch step
    lr: float = 0.01  # Adam step on the kernel hyper-parameters and inducing locations
    natural_gradient: bool = True  # q(u) by natural-gradient steps; false: by Adam with the rest
    ngd_lr: float = 0.1  # natural-gradient step on q(u)
    collapse: bool = True  # the final q(u) is the optimal one on all samples, in closed form (Titsias 2009)
    noise_floor: float = 3e-8  # noise variance floor on standardized targets: sets the error on noise-free data


@dataclass(frozen=True)
class SklearnGPRConfig(ModelConfig):
    kind: ClassVar[str] = "sklearn-gpr"
    hyper_points: int = 500  # the log marginal likelihood is fitted on this many samples
    max_points: int = 5000  # conditioned on at most this many samples (a seeded random subset beyond)
    max_iter: int = 500  # L-BFGS-B iterations of the hyper-parameter fit
    noise_floor: float = 1e-7  # lower bound of the white noise on standardized targets (as gpr)


@dataclass(frozen=True)
class MDNConfig(ModelConfig):
    kind: ClassVar[str] = "mdn"
    hidden: tuple[int, ...] = (64, 64)  # hidden layer widths of the MLP
    n_components: int = 3  # mixture components: kinematics is unimodal, a few absorb noise and contact
    min_std: float = 1e-3  # std floor in standardized units: bounds the precision
    mode: Literal["mean", "max"] = "mean"  # prediction: mixture mean, or mean of the most probable component
    epochs: int = 300  # at most this many passes over the training set
    batch_size: int = 128  # samples per gradient step
    lr: float = 3e-3  # Adam learning rate
    patience: int = 30  # stop after this many epochs without a better validation loss
    weight_decay: float = 0.0  # Adam's L2 penalty
    lr_schedule: Literal["constant", "cosine", "wsd"] = "constant"  # cosine: to 0 over epochs; wsd: in the last 20 %


@dataclass(frozen=True)
class PixelConfig(ModelConfig):
    kind: ClassVar[str] = "pixel"
    size: Literal["lean", "pixel_aif", "splat"] = "lean"  # capacity preset, splat: blobs placed by the joints (SIZES)
    fc_hidden: int | None = None  # width of the fully connected layer; None: the preset's
    channels: tuple[int, ...] | None = None  # one ×2 upsampling per entry; None: the preset's
    refine: bool | None = None  # a 3×3 conv after each upsampling; None: the preset's
    loss: Literal["mse", "cross_entropy"] | None = None  # what the fit minimises per pixel; None: the size's
    precision: float | None = None  # fixed Π_x per pixel; None: 1/σ² of the validation residuals
    epochs: int = 100  # at most this many passes over the training set
    batch_size: int = 64  # images per gradient step
    lr: float | None = None  # Adam learning rate; None: the preset's (lean 4e-3, pixel_aif 2e-3 / mse 5e-4, splat 3e-3)
    patience: int = 10  # stop after this many epochs without a better validation loss
    weight_decay: float = 0.0  # Adam's L2 penalty
    lr_schedule: Literal["constant", "cosine", "wsd"] | None = None  # cosine: to 0 over epochs; wsd: in the last 20 %;
    # None: the preset's (lean wsd, the others constant)
    inputs: Literal["unit", "products", "kinematic"] = "products"  # what the conv sizes' first layer reads of the
    # pose: u, learned products of the joints' (1, cos q, sin q), or all 3^D of them (models/pose_inputs.py)


@dataclass(frozen=True)
class MultimodalConfig(ModelConfig):
    kind: ClassVar[str] = "multimodal"
    # member_hyper ({modality: {name: value}}, per-member overrides) stays a Python-API argument: the CLI sets
    # one value per hyper-parameter, shared by all members (each member's fixed precision via --precisions).
    not_on_cli: ClassVar[tuple[str, ...]] = ("member_hyper",)
    precisions: dict[str, float] | None = None  # fixed precisions, e.g. image 100; the other modalities learn theirs
    joint: bool = True  # fit all members in one loop with one early stopping; False: one after the other
    decoder: Literal["auto", "mlp", "pixel"] = "auto"  # auto: the pixel decoder for images, else an MLP
    hidden: tuple[int, ...] = (64, 64)  # hidden layer widths of the MLP decoders
    fc_hidden: int = 64  # fully connected width of the pixel decoders
    channels: tuple[int, ...] = (32, 16, 8)  # channels of the pixel decoders' upsamplings
    pixel_loss: Literal["cross_entropy", "mse"] = "cross_entropy"  # the pixel decoders' data term (see `train pixel`)
    epochs: int = 200  # at most this many passes over the training set
    batch_size: int = 64  # samples per gradient step
    lr: float = 2e-3  # Adam learning rate of the networks
    patience: int = 15  # stop after this many epochs without a better validation loss
    weight_decay: float = 0.0  # Adam's L2 penalty
    lr_schedule: Literal["constant", "cosine", "wsd"] = "constant"  # cosine: to 0 over epochs; wsd: in the last 20 %
    precision_lr: float = 1e-2  # learning rate of the learned log-precisions λ


@dataclass(frozen=True)
class EncoderConfig(ModelConfig):
    kind: ClassVar[str] = "encoder"
    pool: int | None = None  # average-pool the image by this factor first; None: to at most 80 px a side
    channels: tuple[int, ...] | None = None  # stride-2 convolutions; None: 16, 32, 64, + 64 while the map is > 10 px
    fc_hidden: int = 128  # width of the fully connected head
    epochs: int = 100  # at most this many passes over the training set
    batch_size: int = 64  # images per gradient step
    lr: float | None = None  # Adam learning rate; None: 2e-3 up to 80 px a side (pooled), 5e-4 above
    patience: int = 10  # stop after this many epochs without a better validation loss
    weight_decay: float = 0.0  # Adam's L2 penalty
    lr_schedule: Literal["constant", "cosine", "wsd"] = "constant"  # cosine: to 0 over epochs; wsd: in the last 20 %


# ---- value checks by annotation --------------------------------------------------------------------------
def _accepts(name: str, value, hint) -> bool:
    too_few = name in COUNTS and isinstance(value, int) and value < 1
    return _fits(value, hint) and not too_few


def _fits(value, hint) -> bool:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, a) for a in args)
    if hint is type(None):
        return value is None
    if origin is Literal:
        return value in args
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool) and value >= 0
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0
    if hint is str:
        return isinstance(value, str)
    if origin is tuple:                                 # tuple[int, ...]: layer sizes, each ≥ 1
        return isinstance(value, (tuple, list)) and all(_fits(v, args[0]) and v >= 1 for v in value)
    if origin is dict:                                  # dict[str, float]
        return isinstance(value, dict) and all(_fits(k, args[0]) and _fits(v, args[1]) for k, v in value.items())
    raise TypeError(f"no value check for the annotation {hint!r}: add one to models/configs.py _fits")


def _expected(name: str, hint) -> str:
    return "an integer ≥ 1" if name in COUNTS and hint is int else _describe(hint)


def _describe(hint) -> str:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) for a in args)
    if origin is Literal:
        return f"one of {list(args)}"
    if origin is tuple:
        return "a list of integers ≥ 1"
    if origin is dict:
        return "pairs of a name and a finite number ≥ 0"
    return {bool: "true or false", int: "an integer ≥ 0", float: "a finite number ≥ 0", str: "a word",
            type(None): "None"}[hint]


def _copy(value):
    return dict(value) if isinstance(value, dict) else value
