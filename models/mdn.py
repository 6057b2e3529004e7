"""Mixture density network x ~ Σ_k π_k(z) N(μ_k(z), diag σ_k(z)²) as a SensoryModel (kind "mdn").

An MLP (tanh, smooth so the Jacobian is too) maps scaled joint angles to K mixture components over the
standardized outputs; trained by the negative log-likelihood (Bishop 1994, "Mixture Density Networks").
`predict` is the mixture mean (`mode="mean"`) or the mean of the most probable component (`mode="max"`);
the Jacobian is autograd through that choice; the precision is the inverse expected squared error around
the prediction, Σ_k π_k (σ_k² + (μ_k − x̂)²) — the mixture variance when x̂ is the mixture mean.
The whole density is available too, in output units: `mixture` (its weights, means and stds), `sample` and
`log_prob`, whatever `mode` says.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from bodyschema.errors import must_be
from bodyschema.models._nn_fit import (
    TrainSettings,
    build,
    check_fit_data,
    check_val,
    output_standardizer,
    train,
)
from bodyschema.models._nn_model import NetModel
from bodyschema.models.contract import BaseSensoryModel, as_input, register_kind
from bodyschema.models.scaling import BodySpec

MODES = ("mean", "max")


class MDNNet(nn.Module):
    """u (B, Dz) in [-1, 1] → logits (B, K), means (B, K, O), stds (B, K, O) in standardized output units."""

    def __init__(self, latent_dim: int, n_out: int, hidden: tuple[int, ...], n_components: int, min_std: float):
        super().__init__()
        layers, width = [], latent_dim
        for h in hidden:
            layers += [nn.Linear(width, h), nn.Tanh()]
            width = h
        self.trunk = nn.Sequential(*layers)
        self.head = nn.Linear(width, n_components * (1 + 2 * n_out))
        self.k, self.o, self.min_std = n_components, n_out, min_std

    def forward(self, u):
        p = self.head(self.trunk(u))                                   # (B, K(1 + 2O))
        logits = p[:, :self.k]                                         # (B, K)
        means = p[:, self.k:self.k * (1 + self.o)].reshape(-1, self.k, self.o)      # (B, K, O)
        raw = p[:, self.k * (1 + self.o):].reshape(-1, self.k, self.o)              # (B, K, O)
        return logits, means, nn.functional.softplus(raw) + self.min_std


@register_kind
class MDNModel(NetModel, BaseSensoryModel):
    kind = "mdn"
    precision_varies = True      # 1 / mixture variance at z
    exports_onnx = True

    def __init__(self, body: BodySpec, modality: str, output_shape: tuple[int, ...], *,
                 hidden: tuple[int, ...] = (64, 64),
                 n_components: int = 3,       # forward kinematics is unimodal; a few components absorb noise/contact
                 min_std: float = 1e-3,       # std floor in standardized units: bounds the precision
                 mode: str = "mean",
                 epochs: int = 300, batch_size: int = 128, lr: float = 3e-3, patience: int = 30,
                 weight_decay: float = 0.0, lr_schedule: str = "constant"):
        super().__init__(body, modality, output_shape)
        if mode not in MODES:
            raise ValueError(must_be("mode", f"one of {MODES}", mode))
        if n_components < 1 or min_std <= 0:
            raise ValueError(must_be("n_components and min_std", "≥ 1 and > 0", (n_components, min_std)))
        self.hidden, self.n_components, self.min_std, self.mode = tuple(hidden), n_components, min_std, mode
        self.settings = TrainSettings(epochs, batch_size, lr, patience, weight_decay, lr_schedule)
        self.x_mean_ = self.x_scale_ = None
        self.fit_info_: dict = {}

    # ---- fit ------------------------------------------------------------------------------------------
    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch=None, progress: bool = False, checkpoint=None):
        """Train on q (N, Dz) rad, x (N, *output_shape) by the NLL (`_nn_fit.train`); self."""
        q, x = check_fit_data(q, x, self.latent_dim, self.output_shape)     # (N, Dz), (N, *out)
        val = check_val(val, self.latent_dim, self.output_shape)
        self.x_mean_, self.x_scale_ = output_standardizer(x)             # (O,), (O,)
        gen = torch.Generator().manual_seed(seed)
        net = build(self._factory, gen)
        data = self._training_pair(q, x)
        val = self._training_pair(*val) if val is not None else None
        self.fit_info_ = train(net, _mixture_nll, data, self.settings, gen, val=val, on_epoch=on_epoch,
                               progress=progress, checkpoint=checkpoint, desc="fit mdn")
        self._set_net(net)
        return self

    def _training_pair(self, q, x):
        return self.body.to_unit(q), (x.reshape(x.shape[0], -1) - self.x_mean_) / self.x_scale_

    def _factory(self) -> MDNNet:
        n_out = math.prod(self.output_shape)
        return MDNNet(self.latent_dim, n_out, self.hidden, self.n_components, self.min_std)

    # ---- hooks ----------------------------------------------------------------------------------------
    def _outputs(self, net, u):
        logits, means, stds = net(u)
        x_std = self._point(logits, means)                               # (B, O) standardized
        mean, scale = self.x_mean_.to(u.dtype), self.x_scale_.to(u.dtype)
        return (x_std * scale + mean).reshape(-1, *self.output_shape)

    def _point(self, logits, means):
        weights = logits.softmax(-1)                                     # (B, K)
        if self.mode == "max":   # a one-hot mask (no argmax indexing: it must run under vmap)
            weights = (logits == logits.max(-1, keepdim=True).values).to(logits.dtype)
            weights = weights / weights.sum(-1, keepdim=True)
        return torch.einsum("bk,bko->bo", weights, means)

    def _precision(self, z):
        # Differentiable in z (precision_vjp by autograd); no graph is built unless z requires grad.
        with torch.set_grad_enabled(z.requires_grad):
            logits, means, stds = self._net(z.dtype)(self.body.to_unit(z))
            point = self._point(logits, means)                           # (B, O)
            pi = logits.softmax(-1)[..., None]                           # (B, K, 1)
            second = (pi * (stds ** 2 + (means - point[:, None]) ** 2)).sum(1)   # (B, O) standardized
            var = second * self.x_scale_.to(z.dtype) ** 2
        return (1.0 / var).reshape(-1, *self.output_shape)

    # ---- the density in output units --------------------------------------------------------------------
    def mixture(self, z) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The mixture at z (B, Dz) rad: weights π (B, K), means (B, K, *out) and stds (B, K, *out) in output units."""
        z = self._check_z(z)
        with torch.no_grad():
            log_pi, means, stds = self._components(z)
        shape = (*means.shape[:2], *self.output_shape)
        return log_pi.exp(), means.reshape(shape), stds.reshape(shape)

    def sample(self, z, n: int = 1, generator: torch.Generator | None = None) -> torch.Tensor:
        """n draws of x per z from the mixture: a component by its weight, then its Gaussian. z (B, Dz) rad →
        (n, B, *out) (torch.distributions' order: sample axis first). `generator` on z's device seeds both draws."""
        z = self._check_z(z)
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(must_be("n", "an integer ≥ 1 (draws per z)", n))
        if generator is not None and not isinstance(generator, torch.Generator):
            raise TypeError(must_be("generator", "a torch.Generator or None", type(generator).__name__,
                                    "Seed one with torch.Generator().manual_seed(0)."))
        with torch.no_grad():
            log_pi, means, stds = self._components(z)                                # (B, K), (B, K, O) ×2
            picked = torch.multinomial(log_pi.exp(), n, replacement=True, generator=generator)   # (B, n)
            index = picked[..., None].expand(-1, -1, means.shape[-1])                # (B, n, O)
            noise = torch.randn(index.shape, generator=generator, dtype=z.dtype, device=z.device)
            x = means.gather(1, index) + stds.gather(1, index) * noise               # (B, n, O)
        return x.transpose(0, 1).reshape(n, z.shape[0], *self.output_shape)

    def log_prob(self, z, x) -> torch.Tensor:
        """log p(x | z) of the mixture, in nats per output unit (e.g. ln m⁻³ for ee_xyz). z (B, Dz) rad, x (B, *out)
        → (B,). Differentiable in z and x when they require grad."""
        z = self._check_z(z)
        x = as_input(x)
        if not isinstance(x, torch.Tensor) or tuple(x.shape) != (z.shape[0], *self.output_shape):
            got = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
            raise ValueError(must_be("x", f"of shape ({z.shape[0]}, {', '.join(map(str, self.output_shape))}): "
                                          "one observation per z", got))
        log_pi, means, stds = self._components(z)
        return _log_mixture(log_pi, means, stds, x.reshape(z.shape[0], -1).to(z.dtype))

    def _components(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """log π (B, K), means (B, K, O), stds (B, K, O) in output units: standardized x = (x − mean) / scale."""
        logits, means, stds = self._net(z.dtype)(self.body.to_unit(z.to(self.device)))
        mean, scale = self.x_mean_.to(z.dtype), self.x_scale_.to(z.dtype)
        return (logits.log_softmax(-1).to(z.device), (means * scale + mean).to(z.device),
                (stds * scale).to(z.device))

    def _config(self):
        return {"hidden": list(self.hidden), "n_components": self.n_components, "min_std": self.min_std,
                "mode": self.mode, "epochs": self.settings.epochs, "batch_size": self.settings.batch_size,
                "lr": self.settings.lr, "patience": self.settings.patience,
                "weight_decay": self.settings.weight_decay, "lr_schedule": self.settings.lr_schedule}

    def _state(self):
        return {**super()._state(), "x_mean": self.x_mean_, "x_scale": self.x_scale_}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        model = cls(body, modality, output_shape, **{**config, "hidden": tuple(config["hidden"])})
        model.x_mean_, model.x_scale_ = state["x_mean"], state["x_scale"]
        model._restore_net(model._factory, state)
        return model


def _mixture_nll(net: MDNNet, u: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Mean over the batch of −log p(x | u). u (B, Dz), x (B, O) standardized."""
    logits, means, stds = net(u)
    return -_log_mixture(logits.log_softmax(-1), means, stds, x).mean()


def _log_mixture(log_pi: torch.Tensor, means: torch.Tensor, stds: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """log Σ_k π_k Π_o N(x_o; μ_ko, σ_ko). log_pi (B, K), means and stds (B, K, O), x (B, O) → (B,)."""
    log_n = (-0.5 * ((x[:, None] - means) / stds) ** 2 - stds.log() - 0.5 * math.log(2 * math.pi)).sum(-1)  # (B, K)
    return torch.logsumexp(log_pi + log_n, -1)
