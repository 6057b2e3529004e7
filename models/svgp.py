"""`svgp`: sparse variational GP regression of x = g(z) on any number of poses, with a closed-form Jacobian.

One independent GP per output dimension (as `gpr`: ARD RBF kernel with an output scale over the scaled joints
u ∈ [-1, 1], zero mean on standardized targets, Gaussian noise with a floor, float64), each summarized by M inducing
points U (its own, learned) and a Gaussian q(f(U)): memory O(M²) per output, whatever the number of poses N.

Fitting (`fit`):
1. kernel hyper-parameters start at the exact marginal-likelihood optimum on a seeded random `hyper_points` subset
   (`_gp_hyper.py`, the `gpr` code: seconds);
2. inducing points start at k-means centres of all the poses (`inducing_init="kmeans"`, Lloyd's iterations from a
   seeded random subset) or at a random subset of them;
3. `elbo_epochs` passes of minibatch training of gpytorch's SVGP (Hensman et al. 2013: `VariationalStrategy`, whitened,
   `VariationalELBO`): Adam on the hyper-parameters and inducing locations, natural gradients (`gpytorch.optim.NGD`)
   on q(u) where `natural_gradient` (Salimbeni et al. 2018), else Adam on a Cholesky-parametrized q(u) too;
4. `collapse`: q(u) is then replaced by the optimal one given those hyper-parameters and inducing points, in closed
   form on all N poses (Titsias 2009; the fixed point natural gradients head to), one pass in chunks:
       V = L⁻¹ K_uf,  L Lᵀ = K_uu,  B = σ²I + V Vᵀ = L_B L_Bᵀ            (M, N), (M, M)
       α = L⁻ᵀ B⁻¹ V y        m(z) = k(z, U) α                              posterior mean
       v(z) = s − ‖w‖² + σ²‖L_B⁻¹ w‖²,  w = L⁻¹ k(U, z)                     predictive variance (SGPR)
   Without it the minibatch q(v) = N(m_v, S_v) (whitened) is kept: α = L⁻ᵀ m_v, v(z) = s − ‖w‖² + ‖S_v^½ᵀ w‖².
Both end in α and a triangular factor T with v(z) = s − ‖w‖² + ‖T w‖².

Prediction, Jacobian and variance are closed form (no autograd), as `gpr`'s (R&W eq. 5.1 kernel):
    ∂m/∂u_d = −Σ_j α_j k(u, U_j)(u_d − U_jd)/ℓ_d²
chained through the target de-standardization and the latent scaling rad → [-1, 1]. `device` ("cuda") runs steps
1–4's tensors there; the fitted state comes back to the CPU (perception runs there). Saved state: inducing points,
α, T, hyper-parameters and target scaling; L is recomputed on load. The kernel, L, k-means and the collapsed
posterior are plain tensor functions in `_svgp_math.py`; this module holds the model and its gpytorch training.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from typing import Literal

import gpytorch
import torch
from tqdm.auto import tqdm

from bodyschema.errors import must_be
from bodyschema.models import _gp_data, _gp_hyper
from bodyschema.models._svgp_math import chol_uu, collapsed_posterior, kmeans, rbf
from bodyschema.models.capabilities import GPMemory
from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.device import check_device

STATE_KEYS = ("inducing", "alpha", "cov_factor", "lengthscale", "outputscale", "noise", "y_mean", "y_std")
TRAIN_JITTER = 1e-8    # gpytorch's K_uu jitter in minibatch training (its default for float64 is 1e-6)


class BatchSVGP(gpytorch.models.ApproximateGP):
    """O independent SVGPs in one batched gpytorch model. inducing (O, M, D) in [-1, 1]; targets (O, B)."""

    def __init__(self, inducing: torch.Tensor, natural: bool):
        n_out, m, d = inducing.shape
        batch = torch.Size([n_out])
        # q(v) starts at the prior N(0, I) exactly: gpytorch's default jitters its mean with the global RNG
        kind = (gpytorch.variational.NaturalVariationalDistribution if natural
                else gpytorch.variational.CholeskyVariationalDistribution)
        distribution = kind(m, batch_shape=batch, mean_init_std=0.0)
        strategy = gpytorch.variational.VariationalStrategy(self, inducing, distribution,
                                                            learn_inducing_locations=True, jitter_val=TRAIN_JITTER)
        super().__init__(strategy)
        self.mean_module = gpytorch.means.ZeroMean(batch_shape=batch)
        self.covar_module = gpytorch.kernels.ScaleKernel(
            gpytorch.kernels.RBFKernel(ard_num_dims=d, batch_shape=batch), batch_shape=batch)

    def forward(self, u):
        return gpytorch.distributions.MultivariateNormal(self.mean_module(u), self.covar_module(u))


@register_kind
class SVGPModel(_gp_data.SavedGPState, BaseSensoryModel):
    """Sparse variational GP sensory model, kind "svgp". `__init__` stores hyper-parameters only; `fit` learns."""

    STATE_KEYS = STATE_KEYS
    kind = "svgp"
    precision_varies = True      # 1 / (predictive variance + noise) at z
    exports_onnx = True          # its posterior mean is k(q, U)·α: a few matmuls and one exp, as gpr's
    # The memory guard's n×n matrices are its M×M ones (K_uu, L, q(u)'s factor, their gradients, B, L_B): estimated
    # from the tensors, not measured; `max_points` below is M for the guard. An M×CHUNK block per output besides.
    gp_memory = GPMemory(fit_copies=12.0, condition_copies=16.0, per_output=True)

    def __init__(self, body, modality: str, output_shape: tuple[int, ...], *,
                 num_inducing: int = 1000,    # inducing points per output: O(M²) memory, O(N·M²) for the closed form
                 inducing_init: Literal["kmeans", "random"] = "kmeans",   # where the inducing points start
                 hyper_points: int = 2000,    # starting kernel: the exact MLL on this many samples (Jaco: see README)
                 elbo_epochs: int = 0,        # minibatch ELBO passes (0: the starting kernel and points; see bench)
                 batch_size: int = 1024,      # samples per minibatch step
                 lr: float = 0.01,            # Adam step on the hyper-parameters and inducing locations
                 natural_gradient: bool = True,   # q(u) by natural gradients (NGD); False: by Adam with the rest
                 ngd_lr: float = 0.1,         # natural-gradient step on q(u)
                 collapse: bool = True,       # final q(u): the optimal one on all samples, in closed form
                 noise_floor: float = 3e-8):  # standardized; as gpr's (toy arm: 1e-6 → 25 µm, 3e-8 → 10 µm)
        super().__init__(body, modality, output_shape)
        problems = [must_be(n, f"an integer ≥ {low}", v) for n, v, low in (("num_inducing", num_inducing, 1),
                    ("batch_size", batch_size, 1), ("hyper_points", hyper_points, 2)) if not _is_int(v, low)]
        problems += [must_be("elbo_epochs", "an integer ≥ 0", elbo_epochs)] if not _is_int(elbo_epochs, 0) else []
        problems += [must_be(n, "a finite number > 0", v) for n, v in (("lr", lr), ("ngd_lr", ngd_lr),
                     ("noise_floor", noise_floor)) if not _is_positive(v)]
        problems += [must_be(n, "True or False", v) for n, v in (("natural_gradient", natural_gradient),
                     ("collapse", collapse)) if not isinstance(v, bool)]
        if inducing_init not in ("kmeans", "random"):
            problems.append(must_be("inducing_init", "'kmeans' or 'random'", inducing_init))
        if problems:
            raise ValueError("\n".join(problems))
        self.num_inducing, self.inducing_init, self.hyper_points = int(num_inducing), inducing_init, int(hyper_points)
        self.epochs, self.batch_size = int(elbo_epochs), int(batch_size)
        self.lr, self.ngd_lr = float(lr), float(ngd_lr)
        self.natural_gradient, self.collapse, self.noise_floor = natural_gradient, collapse, float(noise_floor)
        self._chol = None             # L of K_uu (O, M, M); rebuilt lazily after load

    @property
    def is_fitted(self) -> bool:
        return hasattr(self, "alpha_")

    @property
    def max_points(self) -> int:
        """What the exact-GP memory guard (training/guards.py) reads as n: the size of its M×M matrices."""
        return self.num_inducing

    # ---- fitting ------------------------------------------------------------------------------------
    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch: Callable[[int, dict[str, float]], None] | None = None,
            progress: bool = False, device: str = "cpu") -> "SVGPModel":
        """Fit on joint angles q (N, Dz) rad and observations x (N, *output_shape) (numpy or torch). Returns self.

        seed: every random draw (subsets, k-means start, minibatch order). val = (q_val, x_val): scored once at
        the end. on_epoch(epoch, metrics): {"train_neg_elbo"} (−ELBO per sample, summed over outputs, averaged over
        the epoch's steps) after each epoch, then {"val_mean_error", "val_rmse"} when val is given.
        device: where the tensors of the fit live ('cpu', 'cuda', 'cuda:N'); the fitted model is on the CPU.
        """
        dev = check_device(device)
        q, y = _gp_data.check_training_data(q, x, self.body, self.output_shape)        # (N, Dz), (N, O)
        if val is not None:
            val = _gp_data.check_training_data(*val, self.body, self.output_shape, prefix="val ")
        gen = torch.Generator().manual_seed(int(seed))
        u = self.body.to_unit(q)                                                       # (N, Dz)
        ys, y_mean, y_std = _gp_data.standardize(y)                                    # (O, N), (O,), (O,)
        sub = _gp_data.random_subset(u.shape[0], self.hyper_points, gen)
        theta, _, _ = _gp_hyper.fit_log_params(u[sub], ys[:, sub], gen, noise_floor=self.noise_floor, adam_steps=0,
                                            lr=0.05, lbfgs_steps=200)
        lengthscale, outputscale, noise = _gp_hyper.split_log_params(theta)            # (O, D), (O,), (O,)
        m = min(self.num_inducing, u.shape[0])
        start = kmeans(u, m, gen) if self.inducing_init == "kmeans" else u[_gp_data.random_subset(len(u), m, gen)]
        inducing = start[None].expand(ys.shape[0], -1, -1).clone()                    # (O, M, D)
        u, ys = u.to(dev), ys.to(dev)
        if self.epochs > 0:
            gp = self._train(u, ys, inducing.to(dev), (lengthscale, outputscale, noise), gen, on_epoch, progress)
            inducing, lengthscale, outputscale, noise, alpha, factor = _extract(gp)
        if self.collapse or self.epochs == 0:
            lengthscale, outputscale, noise = (t.to(dev) for t in (lengthscale, outputscale, noise))
            alpha, factor = collapsed_posterior(u, ys, inducing.to(dev), lengthscale, outputscale, noise)
        fitted = (inducing, alpha, factor, lengthscale, outputscale, noise)
        (self.inducing_, self.alpha_, self.cov_factor_, self.lengthscale_, self.outputscale_,
         self.noise_) = (t.detach().to("cpu", torch.float64).contiguous() for t in fitted)
        self.y_mean_, self.y_std_ = y_mean, y_std
        self._chol = None
        if val is not None and on_epoch is not None:
            diff = self._predict(val[0]).reshape(val[0].shape[0], -1) - val[1]        # (Nv, O)
            on_epoch(self.epochs, {"val_mean_error": float(diff.norm(dim=-1).mean()),
                                   "val_rmse": float(diff.pow(2).mean().sqrt())})
        return self

    def _train(self, u, ys, inducing, hyper, gen, on_epoch, progress) -> BatchSVGP:
        """Minibatch ELBO training of the batched gpytorch SVGP, started at `hyper` and `inducing`."""
        lengthscale, outputscale, noise = hyper
        n_out, n = ys.shape
        gp = BatchSVGP(inducing, self.natural_gradient).to(u.device, torch.float64)
        gp.covar_module.base_kernel.lengthscale = lengthscale[:, None, :].to(u.device)
        gp.covar_module.outputscale = outputscale.to(u.device)
        likelihood = gpytorch.likelihoods.GaussianLikelihood(
            batch_shape=torch.Size([n_out]), noise_constraint=gpytorch.constraints.GreaterThan(self.noise_floor))
        likelihood = likelihood.to(u.device, torch.float64)
        likelihood.noise = noise[:, None].clamp_min(self.noise_floor * 1.0001).to(u.device)
        elbo = gpytorch.mlls.VariationalELBO(likelihood, gp, num_data=n)
        variational = list(gp.variational_parameters())
        rest = [p for p in [*gp.hyperparameters(), *likelihood.parameters()]]
        optimizers = [torch.optim.Adam(rest + ([] if self.natural_gradient else variational), lr=self.lr)]
        if self.natural_gradient:
            optimizers.append(gpytorch.optim.NGD(variational, num_data=n, lr=self.ngd_lr))
        gp.train()
        likelihood.train()
        steps = math.ceil(n / self.batch_size)
        bar = tqdm(total=self.epochs * steps, desc="svgp", disable=not progress, leave=False)
        with exact_solves():
            for epoch in range(self.epochs):
                order = torch.randperm(n, generator=gen).to(u.device)
                total = 0.0
                for i in range(steps):
                    idx = order[i * self.batch_size:(i + 1) * self.batch_size]
                    for opt in optimizers:
                        opt.zero_grad()
                    out = gp(u[idx].expand(n_out, -1, -1))                     # (O, B) latent
                    loss = -elbo(out, ys[:, idx]).sum()                         # per sample, summed over outputs
                    loss.backward()
                    for opt in optimizers:
                        opt.step()
                    total += float(loss.detach())
                    bar.update()
                if on_epoch is not None:
                    on_epoch(epoch, {"train_neg_elbo": total / steps})
        bar.close()
        gp.eval()
        gp.noise_ = likelihood.noise.detach().reshape(n_out)
        return gp

    # ---- closed-form prediction ---------------------------------------------------------------------
    def _kernel(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        u = self.body.to_unit(z.to(torch.float64))                                     # (B, Dz)
        return u, rbf(u, self.inducing_, self.lengthscale_, self.outputscale_)         # (O, B, M)

    def _mean_and_jacobian(self, u: torch.Tensor, k: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """m (B, O) in output units and ∂m/∂z (B, O, Dz) per rad, from one kernel matrix k (O, B, M)."""
        x1 = torch.cat([self.inducing_, torch.ones_like(self.inducing_[..., :1])], -1)   # (O, M, D+1)
        moments = k @ (self.alpha_[..., None] * x1)                                    # (O, B, D+1): Σ w U, Σ w
        mean = moments[..., -1]                                                        # (O, B) standardized
        jac = -(u[None] * mean[..., None] - moments[..., :-1]) / self.lengthscale_.pow(2)[:, None, :]  # (O, B, D)
        jac = jac.transpose(0, 1) * self.y_std_[:, None] * self.body.unit_per_rad(u)   # (B, O, Dz)
        return mean.T * self.y_std_ + self.y_mean_, jac

    def _predict(self, z):
        _, k = self._kernel(z)
        mean = (k @ self.alpha_[:, :, None]).squeeze(-1).T * self.y_std_ + self.y_mean_   # (B, O)
        return mean.reshape(z.shape[0], *self.output_shape)

    def _jacobian(self, z):
        return self._mean_and_jacobian(*self._kernel(z))[1]

    def _vjp(self, z, v):
        return torch.einsum("bod,bo->bd", self._jacobian(z), v.reshape(v.shape[0], -1).to(torch.float64))

    def predict_with_jacobian(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """predict(z) and jacobian(z) sharing one kernel matrix. → (B, *out), (B, O, Dz)."""
        z = self._check_z(z)
        mean, jac = self._mean_and_jacobian(*self._kernel(z))
        return mean.reshape(z.shape[0], *self.output_shape).to(z.dtype), jac.to(z.dtype)

    def _precision(self, z):
        """1 / (σ²_pred + σ²_noise) in output units⁻², diagonal. # (B, *out)"""
        _, k = self._kernel(z)
        w = torch.linalg.solve_triangular(self.chol, k.mT, upper=False)                # (O, M, B): L⁻¹ k(U, z)
        var = self.outputscale_[:, None] - w.pow(2).sum(-2) + (self.cov_factor_ @ w).pow(2).sum(-2)   # (O, B)
        var_out = (var.clamp_min(0.0) + self.noise_[:, None]) * self.y_std_[:, None].pow(2)
        return (1.0 / var_out).T.reshape(z.shape[0], *self.output_shape)

    @property
    def chol(self) -> torch.Tensor:
        """L of K_uu + jitter (O, M, M): recomputed on first use after fit or load."""
        if self._chol is None:
            self._chol = chol_uu(self.inducing_, self.lengthscale_, self.outputscale_)
        return self._chol

    # ---- persistence --------------------------------------------------------------------------------
    def _config(self):
        return {"num_inducing": self.num_inducing, "inducing_init": self.inducing_init,
                "hyper_points": self.hyper_points, "elbo_epochs": self.epochs, "batch_size": self.batch_size,
                "lr": self.lr, "natural_gradient": self.natural_gradient, "ngd_lr": self.ngd_lr,
                "collapse": self.collapse, "noise_floor": self.noise_floor}


# ---- fitting helpers ------------------------------------------------------------------------------------
def exact_solves():
    """gpytorch with Cholesky solves at every size (its default turns to CG above 800 points)."""
    stack = contextlib.ExitStack()
    stack.enter_context(gpytorch.settings.max_cholesky_size(10**9))
    stack.enter_context(gpytorch.settings.fast_computations(False, False, False))
    return stack


def _extract(gp: BatchSVGP):
    """(inducing, lengthscale, outputscale, noise, α, T) of a trained BatchSVGP: its whitened q(v) = N(m_v, S_v)
    as α = L⁻ᵀ m_v and T = (S_v^½)ᵀ, with L recomputed here as the closed form computes it."""
    with torch.no_grad():
        inducing = gp.variational_strategy.inducing_points.detach().clone()        # (O, M, D)
        lengthscale = gp.covar_module.base_kernel.lengthscale.detach().squeeze(-2).clone()   # (O, D)
        outputscale = gp.covar_module.outputscale.detach().clone()                 # (O,)
        q_v = gp.variational_strategy.variational_distribution
        chol = chol_uu(inducing, lengthscale, outputscale)
        alpha = torch.linalg.solve_triangular(chol.mT, q_v.mean[..., None], upper=True).squeeze(-1)   # (O, M)
        factor = torch.linalg.cholesky(q_v.covariance_matrix).mT.contiguous()     # (O, M, M)
    return inducing, lengthscale, outputscale, gp.noise_, alpha, factor


def _is_int(value, low: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _is_positive(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
