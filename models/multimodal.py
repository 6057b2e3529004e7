"""One decoder per modality over one shared latent z: `MultimodalModel` and its members (kind "multimodal").

A member is a SensoryModel: an MLP (tanh, standardized outputs) for vector modalities (joints, ee_xyz,
ee_pixel, touch) or the pixel decoder's network for images, plus a log-precision λ per modality. Training
minimises the Gaussian negative log-likelihood per output, 0.5·e^λ·r² − 0.5·λ (+ const), so λ converges to
−log of the residual variance: each modality learns how much to be trusted (Friston 2010: precision-weighted
prediction errors). A precision set by the caller replaces λ (then the loss is the plain squared error).
A pixel member fits its decoder by `pixel_loss` (pixel.py's LOSSES): by default the cross-entropy on the logits,
whose gradient does not vanish where the squared error's through the sigmoid does (an arm covering 2 % of a black
image: SO-101 at 64×64 went black for every pose), weighted by e^λ as the squared error is; λ still converges to
−log of the residual variance (`_cross_entropy_nll`).
`MultimodalModel` holds `members: dict[modality, member]` (what the AIF consumes: SensoryModels over the
same z), fits them jointly (one loop, one early stopping on the summed loss) or one by one, and saves one
sub-directory per member plus `multimodal.json`.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import torch
from torch import nn
from torch.nn import functional as F

from bodyschema.base.modalities import is_image
from bodyschema.errors import must_be
from bodyschema.models._nn_fit import (
    LeafParams,
    TrainSettings,
    build,
    check_fit_data,
    check_val,
    output_standardizer,
    train,
)
from bodyschema.models._nn_model import NetModel
from bodyschema.models.capabilities import Capabilities
from bodyschema.models.contract import BaseSensoryModel, load_model, register_kind
from bodyschema.models.estimator import Estimator
from bodyschema.models.pixel import CONV_LOSS, LOSSES, PixelDecoderNet, fast_layout
from bodyschema.models.scaling import BodySpec

DECODERS = ("auto", "mlp", "pixel")
MANIFEST = "multimodal.json"
MEMBER_OWN = ("body", "modality", "output_shape", "precision")   # member params that MultimodalModel sets per member


class MemberNet(nn.Module):
    """The decoder and the modality's log-precision λ (standardized units)."""

    def __init__(self, decoder: nn.Module):
        super().__init__()
        self.decoder = decoder
        self.noise = LeafParams(log_precision=())


@register_kind
class MultimodalMember(NetModel, BaseSensoryModel):
    kind = "multimodal"
    exports_onnx = True
    sweepable = False      # fitted with the other members, by `bodyschema train multimodal`

    def __init__(self, body: BodySpec, modality: str, output_shape: tuple[int, ...], *,
                 decoder: str = "auto",                  # auto: "pixel" for (H, W[, C]) images, else "mlp"
                 hidden: tuple[int, ...] = (64, 64),     # mlp
                 fc_hidden: int = 64, channels: tuple[int, ...] = (32, 16, 8),   # pixel (see pixel.py)
                 pixel_loss: str = CONV_LOSS,            # pixel: the decoder's data term (pixel.py's LOSSES)
                 precision: float | None = None,         # None: learned λ; else fixed, in output units⁻²
                 epochs: int = 200, batch_size: int = 64, lr: float = 2e-3, patience: int = 15,
                 weight_decay: float = 0.0, lr_schedule: str = "constant",
                 precision_lr: float = 1e-2):   # λ moves ~precision_lr per step
        super().__init__(body, modality, output_shape)
        if decoder not in DECODERS:
            raise ValueError(must_be("decoder", f"one of {DECODERS}", decoder))
        if decoder == "auto":
            decoder = "pixel" if is_image(modality) or len(self.output_shape) >= 2 else "mlp"
        if precision is not None and not precision > 0:
            raise ValueError(must_be("precision", "> 0 or None (learned)", precision))
        if pixel_loss not in LOSSES:
            raise ValueError(must_be("pixel_loss", f"one of {sorted(LOSSES)}", pixel_loss))
        self.pixel_loss = pixel_loss
        self.decoder, self.hidden, self.fc_hidden, self.channels = decoder, tuple(hidden), fc_hidden, tuple(channels)
        self.fixed_precision, self.precision_lr = precision, precision_lr
        self.settings = TrainSettings(epochs, batch_size, lr, patience, weight_decay, lr_schedule)
        self.x_mean_ = self.x_scale_ = None
        self.fit_info_: dict = {}

    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch=None, progress: bool = False, checkpoint=None):
        """Train on q (N, Dz) rad, x (N, *output_shape) by `_nll` (`_nn_fit.train`); self."""
        val = None if val is None else (val[0], {self.modality: val[1]}) if isinstance(val, (tuple, list)) else val
        fit_jointly({self.modality: self}, q, {self.modality: x}, seed=seed, val=val, on_epoch=on_epoch,
                    progress=progress, checkpoint=checkpoint, settings=self.settings)
        return self

    # ---- training pieces (used by fit_jointly) ---------------------------------------------------------
    def _prepare(self, x: torch.Tensor) -> None:
        if self.decoder == "pixel":   # images stay in [0, 1]: the sigmoid output is already there
            n_out = math.prod(self.output_shape)
            self.x_mean_, self.x_scale_ = torch.zeros(n_out), torch.ones(n_out)
        else:
            self.x_mean_, self.x_scale_ = output_standardizer(x)                    # (O,), (O,)

    def _target(self, x: torch.Tensor) -> torch.Tensor:
        return (x.reshape(x.shape[0], -1) - self.x_mean_) / self.x_scale_             # (N, O)

    @property
    def convolutional(self) -> bool:
        return self.decoder == "pixel"

    def _factory(self) -> MemberNet:
        if self.decoder == "pixel":
            return fast_layout(MemberNet(PixelDecoderNet(self.latent_dim, self.output_shape, self.fc_hidden,
                                                         self.channels)))
        layers, width = [], self.latent_dim
        for h in self.hidden:
            layers += [nn.Linear(width, h), nn.Tanh()]
            width = h
        return MemberNet(nn.Sequential(*layers, nn.Linear(width, math.prod(self.output_shape))))

    def _nll(self, net: MemberNet, u: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Gaussian NLL per output, mean over batch and outputs (a pixel member by the cross-entropy: its own).
        u (B, Dz), target (B, O) standardized."""
        if self.decoder == "pixel" and self.pixel_loss == "cross_entropy":
            return self._cross_entropy_nll(net, u, target)
        r2 = (net.decoder(u).reshape(u.shape[0], -1) - target).pow(2)               # (B, O)
        if self.fixed_precision is not None:
            return 0.5 * r2.mean()
        lam = net.noise.log_precision
        return (0.5 * lam.exp() * r2 - 0.5 * lam).mean()

    def _cross_entropy_nll(self, net: MemberNet, u: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """The cross-entropy on the logits less its least value (a KL, 0 at a perfect fit), plus λ's Gaussian NLL on
        the detached residuals (λ learns their variance as above). The KL's gradient is weighted by e^λ, as the
        Gaussian NLL's is: λ grows during the fit and Adam's steps with it (nao_arm, two cameras: floor 4.4°
        unweighted, 3.1° weighted). Its value is not: weighted, it would grow with λ while the fit improves, and
        early stopping reads it. u (B, Dz), target (B, O) in [0, 1]."""
        logits = net.decoder.logits(u).reshape(u.shape[0], -1)                      # (B, O)
        kl = F.binary_cross_entropy_with_logits(logits, target) - _bernoulli_entropy(target)
        if self.fixed_precision is not None:
            return kl
        lam = net.noise.log_precision
        r2 = (logits.sigmoid() - target).pow(2).detach()
        weighted = kl.detach() + lam.detach().exp() * (kl - kl.detach())           # value kl, gradient e^λ·∇kl
        return weighted + (0.5 * lam.exp() * r2 - 0.5 * lam).mean()

    # ---- hooks ----------------------------------------------------------------------------------------
    def _outputs(self, net, u):
        y = net.decoder(u)
        if self.decoder == "pixel":
            return y
        y = y * self.x_scale_.to(u.dtype) + self.x_mean_.to(u.dtype)                  # (B, O)
        return y.reshape(-1, *self.output_shape)

    def _precision(self, z):
        if self.fixed_precision is not None:
            return torch.full((z.shape[0], *self.output_shape), self.fixed_precision, dtype=z.dtype)
        lam = self.net_.noise.log_precision.double()
        per_output = (lam.exp() / self.x_scale_.double() ** 2).to(z.dtype)          # (O,) in output units⁻²
        return per_output.expand(z.shape[0], -1).reshape(-1, *self.output_shape).clone()

    def _config(self):
        return {"decoder": self.decoder, "hidden": list(self.hidden), "fc_hidden": self.fc_hidden,
                "channels": list(self.channels), "pixel_loss": self.pixel_loss, "precision": self.fixed_precision,
                "epochs": self.settings.epochs, "batch_size": self.settings.batch_size, "lr": self.settings.lr,
                "patience": self.settings.patience, "weight_decay": self.settings.weight_decay,
                "lr_schedule": self.settings.lr_schedule,
                "precision_lr": self.precision_lr}

    def _state(self):
        return {**super()._state(), "x_mean": self.x_mean_, "x_scale": self.x_scale_}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        model = cls(body, modality, output_shape,   # saved before pixel_loss existed: fitted by the squared error
                    **{"pixel_loss": "mse", **config, "hidden": tuple(config["hidden"]),
                       "channels": tuple(config["channels"])})
        model.x_mean_, model.x_scale_ = state["x_mean"], state["x_scale"]
        model._restore_net(model._factory, state)
        return model


def fit_jointly(members: dict[str, MultimodalMember], q, xs: dict, *, seed: int, val, on_epoch, progress: bool,
                checkpoint, settings: TrainSettings) -> dict:
    """Train all members in one loop over shared minibatches; the loss is the sum of the members' NLLs."""
    _check_keys("xs", xs, members)
    names = list(members)
    first = members[names[0]]
    pairs = [check_fit_data(q, xs[m], first.latent_dim, members[m].output_shape, name=f"xs[{m!r}]") for m in names]
    q = pairs[0][0]                                                               # (N, Dz) rad
    val_pairs = None
    if val is not None:
        if not isinstance(val, (tuple, list)) or len(val) != 2 or not isinstance(val[1], dict):
            raise TypeError(must_be("val", "a pair (q_val, {modality: x_val}) or None", type(val).__name__))
        _check_keys("val[1]", val[1], members)
        val_pairs = [check_val((val[0], val[1][m]), first.latent_dim, members[m].output_shape) for m in names]
    gen = torch.Generator().manual_seed(seed)
    nets = nn.ModuleDict()
    for m, (_, x) in zip(names, pairs):
        members[m]._prepare(x)
        nets[m] = build(members[m]._factory, gen)
        if members[m].decoder == "pixel":   # start at the precision of a constant predictor: 1 / var(x)
            nets[m].noise.log_precision.data.fill_(-math.log(max(float(x.var()), 1e-8)))

    def joint_nll(module, u, *targets):
        return sum(members[m]._nll(module[m], u, t) for m, t in zip(names, targets))

    def tensors(q_, xs_):
        return (first.body.to_unit(q_), *(members[m]._target(x) for m, x in zip(names, xs_)))

    learned = [nets[m].noise.log_precision for m in names if members[m].fixed_precision is None]
    groups = [{"params": [p for m in names for p in nets[m].decoder.parameters()]}]
    groups += [{"params": learned, "lr": first.precision_lr}] if learned else []
    info = train(nets, joint_nll, tensors(q, [x for _, x in pairs]), settings, gen,
                 val=tensors(val_pairs[0][0], [x for _, x in val_pairs]) if val_pairs else None,
                 on_epoch=on_epoch, progress=progress, checkpoint=checkpoint, param_groups=groups,
                 desc=f"fit {'+'.join(names)}")
    for m in names:
        members[m]._set_net(nets[m])
        members[m].fit_info_ = info
    return info


def _bernoulli_entropy(x: torch.Tensor) -> torch.Tensor:
    """The least cross-entropy of targets x in [0, 1], mean per output: subtracted, the data term is a KL ≥ 0."""
    return -(torch.xlogy(x, x) + torch.xlogy(1 - x, 1 - x)).mean()


def _prefixed(on_epoch, modality: str):
    """Per-member metrics for MLflow: {"ee_xyz/train_loss": ...}."""
    return lambda epoch, metrics: on_epoch(epoch, {f"{modality}/{k}": v for k, v in metrics.items()})


def _check_keys(what: str, d, members) -> None:
    if not isinstance(d, dict) or set(d) != set(members):
        got = sorted(d) if isinstance(d, dict) else type(d).__name__
        raise ValueError(must_be(what, f"a dict with exactly the modalities {sorted(members)}", got))


class MultimodalModel(Estimator, Capabilities):
    """Members over one shared z. `output_shapes`: {modality: per-sample shape}; `member_hyper`: per-member
    overrides of the shared hyper-parameters; `precisions`: {modality: fixed precision} (others are learned)."""

    kind = "multimodal"
    network = has_members = True     # trained as one; each member is saved, registered and exported on its own
    onnx_hint = "Export each member, one file per modality: model.members[modality]"

    def __init__(self, body: BodySpec, output_shapes: dict[str, tuple[int, ...]], *,
                 member_hyper: dict[str, dict] | None = None, precisions: dict[str, float] | None = None,
                 joint: bool = True, **shared_hyper):
        if not output_shapes:
            raise ValueError(must_be("output_shapes", "a non-empty dict {modality: shape}", output_shapes))
        member_hyper, precisions = member_hyper or {}, precisions or {}
        for what, d in (("member_hyper", member_hyper), ("precisions", precisions)):
            if set(d) - set(output_shapes):
                raise ValueError(must_be(f"{what} keys", f"among the modalities {sorted(output_shapes)}", sorted(d)))
        self.body, self.joint = body, joint
        self.members: dict[str, MultimodalMember] = {
            m: MultimodalMember(body, m, tuple(shape), precision=precisions.get(m),
                                **{**shared_hyper, **member_hyper.get(m, {})})
            for m, shape in output_shapes.items()}

    @property
    def is_fitted(self) -> bool:
        return all(member.is_fitted for member in self.members.values())

    def _modality_label(self) -> str:
        return ",".join(self.members)

    @property
    def precisions(self) -> dict[str, torch.Tensor]:
        """Per-modality precision at z = centre of the joint ranges. {modality: (*output_shape,)}"""
        z = self.body.from_unit(torch.zeros(1, self.body.latent_dim, dtype=torch.float64))
        return {m: member.precision(z)[0] for m, member in self.members.items()}

    def predict(self, z: torch.Tensor) -> dict[str, torch.Tensor]:
        return {m: member.predict(z) for m, member in self.members.items()}

    def fit(self, q, xs: dict, *, seed: int = 0, val=None, on_epoch=None, progress: bool = False, checkpoint=None):
        """xs: {modality: (N, *shape)}; val: (q_val, {modality: x_val}); checkpoint: a file (joint) or stem."""
        _check_keys("xs", xs, self.members)
        if self.joint:
            first = next(iter(self.members.values()))
            fit_jointly(self.members, q, xs, seed=seed, val=val, on_epoch=on_epoch, progress=progress,
                        checkpoint=checkpoint, settings=first.settings)
            return self
        for i, (m, member) in enumerate(self.members.items()):
            ckpt = None if checkpoint is None else Path(checkpoint).with_name(f"{Path(checkpoint).stem}.{m}.pt")
            report = None if on_epoch is None else _prefixed(on_epoch, m)
            member.fit(q, xs[m], seed=seed + i, val=None if val is None else (val[0], val[1][m]),
                       on_epoch=report, progress=progress, checkpoint=ckpt)
        return self

    def save(self, path: str | Path) -> None:
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        for m, member in self.members.items():
            member.save(path / m)
        manifest = {"format_version": 1, "modalities": list(self.members), "joint": self.joint,
                    "body": self.body.to_dict()}
        (path / MANIFEST).write_text(json.dumps(manifest, indent=2))

    @classmethod
    def load(cls, path: str | Path) -> "MultimodalModel":
        path = Path(path)
        if not (path / MANIFEST).is_file():
            raise FileNotFoundError(must_be("path", f"a directory holding {MANIFEST}", str(path),
                                            "Pass the directory given to MultimodalModel.save()."))
        manifest = json.loads((path / MANIFEST).read_text())
        body = BodySpec.from_dict(manifest["body"])
        members = {m: load_model(path / m) for m in manifest["modalities"]}
        for m, member in members.items():
            body.check_compatible(member.body, what=f"member {m!r}")
        # Built from the members' own params (so get_params and clone describe what was loaded), then given them.
        params = {m: member.get_params() for m, member in members.items()}
        model = cls(body, {m: member.output_shape for m, member in members.items()}, joint=manifest["joint"],
                    precisions={m: p["precision"] for m, p in params.items() if p["precision"] is not None},
                    member_hyper={m: {k: v for k, v in p.items() if k not in MEMBER_OWN} for m, p in params.items()})
        model.members = members
        return model
