"""`gpr`: exact Gaussian-process regression of x = g(z), with a closed-form Jacobian.

One independent GP per output dimension: zero mean on standardized targets, learned Gaussian noise with a low floor,
float64, and one of two kernels with an output scale (`kernel`):
- "rbf": ARD RBF over the scaled joints. `to_gpytorch` gives the same GP as ONE batched gpytorch model
  (batch_shape = n_outputs), for comparisons;
- "kinematic": s Π_d (c_d + cos Δq_d) / (1 + c_d) (`_gp_trig.py`), exact for a point carried by revolute joints
  (the end effector in 3-D): 1e-5 mm where the RBF is 30–100 mm off over a 6–7-joint arm's full ranges;
- "auto" (the default): both are fitted to the hyper subset and the one of higher marginal likelihood is kept (the
  data decide: kinematic on every arm's ee_xyz measured, and on a UR5's ee_pixel, 4.4 px held-out against the
  RBF's 5.7; the RBF for what no trig polynomial holds); the kinematic one only up to 7 joints (3^D features).

Fitting (`fit`):
1. at most `max_points` samples are kept (a seeded uniform random subset beyond that) for the likelihood and the RBF;
   the kinematic kernel is conditioned on every sample (its feature form costs O(n·9^D) time, O(9^D) memory);
2. hyper-parameters maximize the exact marginal likelihood on a seeded random subset of `hyper_points` samples
   (`_gp_hyper.py`: closed-form MLL and gradient, L-BFGS-B per output, coarse then fine). No gpytorch solve is
   involved: its default silently switches to approximate CG solves above 800 points (measured 55 mm instead of
   0.003 mm mean error on nao_arm, 2000 poses);
3. the GP is conditioned on all kept samples with our own Cholesky: α = (K + σ²I)⁻¹ y (see `_gp_math.py`; the
   kinematic kernel in its feature form instead, `_gp_trig.TrigPosterior`). `condition(q, x)` re-does only this step.

Prediction, Jacobian (no autograd) and variance are closed form from the cached α (`_gp_math.py`), then
chained through the target de-standardization and the latent scaling rad → [-1, 1]; `predict_with_jacobian`
shares one kernel matrix between both. Saved state: hyper-parameters, scaled training inputs, α and the target
scaling; the Cholesky factor (only the precision needs it) is recomputed on first use after a load.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Literal

import gpytorch
import torch

from bodyschema.errors import must_be
from bodyschema.models import _gp_data, _gp_hyper, _gp_math, _gp_trig
from bodyschema.models.capabilities import GPMemory
from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.scaling import BodySpec

STATE_KEYS = ("train_u", "alpha", "lengthscale", "outputscale", "noise", "y_mean", "y_std")
TRIG_STATE_KEYS = ("train_u", "weights", "offset", "outputscale", "noise", "y_mean", "y_std")
KERNELS = ("auto", "rbf", "kinematic")
_log = logging.getLogger(__name__)
# noise_floor: noise-free targets fit with σ² at the floor, so it sets their error (regularization), e.g. nao_arm
# 2000 poses: 1e-7 / 3e-8 / 1e-8 → 1.33 / 0.72 / 0.42 µm mean; 1e-9 let the output scale run away (2.3 µm). 3e-8
# keeps a margin from that and beats sklearn-gpr's 1.09 µm (its floor 1e-7, one kernel shared by the outputs).


class BatchExactGP(gpytorch.models.ExactGP):
    """O independent exact GPs in one batched model. train_u (O, n, D) in [-1, 1], train_y (O, n) standardized."""

    def __init__(self, train_u: torch.Tensor, train_y: torch.Tensor, likelihood):
        super().__init__(train_u, train_y, likelihood)
        batch = torch.Size([train_y.shape[0]])
        self.mean_module = gpytorch.means.ZeroMean(batch_shape=batch)
        self.covar_module = gpytorch.kernels.ScaleKernel(
            gpytorch.kernels.RBFKernel(ard_num_dims=train_u.shape[-1], batch_shape=batch), batch_shape=batch)

    def forward(self, u):
        return gpytorch.distributions.MultivariateNormal(self.mean_module(u), self.covar_module(u))


def build_exact_gp(train_u: torch.Tensor, train_y: torch.Tensor, noise_floor: float,
                   lengthscale: float | torch.Tensor = 0.5, outputscale: float | torch.Tensor = 1.0,
                   noise: float | torch.Tensor = 1e-3) -> BatchExactGP:
    """A float64 batched gpytorch GP. train_u (n, D), train_y (O, n); hyper-parameters scalar or (O, D)/(O,)."""
    n_out = train_y.shape[0]
    likelihood = gpytorch.likelihoods.GaussianLikelihood(
        batch_shape=torch.Size([n_out]), noise_constraint=gpytorch.constraints.GreaterThan(noise_floor))
    gp = BatchExactGP(train_u.expand(n_out, *train_u.shape), train_y, likelihood).double()
    likelihood.double()
    gp.covar_module.base_kernel.lengthscale = _filled(lengthscale, (n_out, 1, train_u.shape[-1]))
    gp.covar_module.outputscale = _filled(outputscale, (n_out,))
    likelihood.noise = _filled(noise, (n_out, 1)).clamp_min(noise_floor * 1.0001)
    return gp


def _filled(value, shape) -> torch.Tensor:
    """A float64 tensor of `shape` holding `value` (a scalar or a broadcastable array), one per output GP."""
    return torch.as_tensor(value, dtype=torch.float64).expand(shape).clone()


@register_kind
class GPRModel(_gp_data.SavedGPState, BaseSensoryModel):
    """Exact GP sensory model, kind "gpr". `__init__` stores hyper-parameters only; `fit` learns."""

    kind = "gpr"
    precision_varies = True      # 1 / (predictive variance + noise) at z
    exports_onnx = True          # its posterior mean is a few matmuls and one exp, or cos/sin, products and one matmul
    # measured peak (bench: ru_maxrss, training/guards.py): autograd keeps the kernel, its Cholesky and gradients
    gp_memory = GPMemory(fit_copies=12.0, condition_copies=3.0, per_output=True)

    def __init__(self, body: BodySpec, modality: str, output_shape: tuple[int, ...], *,
                 hyper_points: int = 500,     # MLL fitted on this many samples: O(m³) per evaluation (~10 ms)
                 max_points: int = 5000,      # RBF: conditioned on at most this many (O(n³) once, O(n²) memory per
                                              # output); the kinematic kernel takes all (O(n·9^Dz), O(9^Dz) memory)
                 adam_steps: int = 0,         # optional Adam steps between the coarse and fine L-BFGS-B runs
                 lbfgs_steps: int = 200,      # max MLL evaluations per L-BFGS-B run (each output, coarse and fine)
                 lr: float = 0.05,            # Adam step on the log hyper-parameters
                 noise_floor: float = 3e-8,   # standardized targets; see the noise_floor note above
                 kernel: Literal["auto", "rbf", "kinematic"] = "auto"):   # see the module doc
        super().__init__(body, modality, output_shape)
        _gp_data.check_gp_hyper(hyper_points, max_points, noise_floor)
        check_kernel(kernel, self.latent_dim)
        self.kernel = kernel
        self.hyper_points, self.max_points = int(hyper_points), int(max_points)
        self.adam_steps, self.lbfgs_steps, self.lr = int(adam_steps), int(lbfgs_steps), float(lr)
        self.noise_floor = float(noise_floor)
        self._factor = None                   # Cholesky of K + σ²I, (O, n, n); rebuilt lazily after load
        self._trig = None                     # the kinematic kernel's posterior (`_gp_trig.TrigPosterior`)

    @property
    def STATE_KEYS(self) -> tuple[str, ...]:  # noqa: N802 (SavedGPState's name)
        return TRIG_STATE_KEYS if self.kernel_ == "kinematic" else STATE_KEYS

    @property
    def fitted_choices(self) -> str:
        if not self.is_fitted or self.kernel != "auto":
            return ""
        return f"Kernel {self.kernel_}: the likelier of {' and '.join(candidate_kernels('auto', self.latent_dim))}."

    @property
    def is_fitted(self) -> bool:
        return hasattr(self, "alpha_") or hasattr(self, "weights_")

    # ---- fitting ------------------------------------------------------------------------------------
    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch: Callable[[int, dict[str, float]], None] | None = None,
            progress: bool = False) -> "GPRModel":
        """Fit on joint angles q (N, Dz) rad and observations x (N, *output_shape) (numpy or torch). Returns self.

        seed: the random subsets (max_points, hyper_points). val = (q_val, x_val): evaluated once after fitting.
        on_epoch(step, metrics): every marginal-likelihood evaluation {"train_neg_mll"} (−MLL per point, summed
        over outputs, each at its latest evaluation), then {"val_mean_error", "val_rmse"} (output units: mean
        per-sample Euclidean error, RMSE over all output elements, as training.scoring.score) when val is given.
        """
        q_all, y_all, keep, val, gen = _gp_data.training_data(self, q, x, val, seed)  # (N, Dz), (N, O), (n,)
        u = self.body.to_unit(q_all[keep])                                            # (n, Dz)
        ys, self.y_mean_, self.y_std_ = _gp_data.standardize(y_all[keep])             # (O, n), (O,), (O,)
        sub = _gp_data.random_subset(u.shape[0], self.hyper_points, gen)
        step = self._fit_hyper(u[sub], ys[:, sub], gen, on_epoch, progress)
        sums = None
        if self.kernel_ == "kinematic":      # its feature form takes every pose, not the max_points subset
            u, ys = self.body.to_unit(q_all), self._standardized(y_all)               # (N, Dz), (O, N)
            sums = _gp_trig.moments(self.body.from_unit(u), ys)                       # ΦᵀΦ, Φᵀy: once, the O(N·9^Dz)
            self._settle_offsets(sums, ys)
        self._condition_unit(u, ys, sums)
        if val is not None and on_epoch is not None:
            pred = self._predict(val[0])                                              # (Nv, *out)
            diff = pred.reshape(pred.shape[0], -1) - val[1]                           # (Nv, O)
            on_epoch(step, {"val_mean_error": float(diff.norm(dim=-1).mean()),
                            "val_rmse": float(diff.pow(2).mean().sqrt())})
        return self

    def _fit_hyper(self, u: torch.Tensor, ys: torch.Tensor, gen: torch.Generator, on_epoch, progress: bool) -> int:
        """The kernel and its hyper-parameters at the highest marginal likelihood on the hyper subset (u (m, Dz) in
        [-1, 1], ys (O, m)); "auto" fits both kernels and keeps the better. → the number of MLL evaluations."""
        fits, step = {}, 0
        for kernel in candidate_kernels(self.kernel, self.latent_dim):     # rbf first: its fit is as before
            def log_step(i, metrics, offset=step):                         # one step count over both searches
                on_epoch(offset + i, metrics)
            inputs, objective = ((u, _gp_math.neg_mll_and_grad) if kernel == "rbf" else
                                 (self.body.from_unit(u), _gp_trig.neg_mll_and_grad))
            theta, loss, steps = _gp_hyper.fit_log_params(
                inputs, ys, gen, noise_floor=self.noise_floor, adam_steps=self.adam_steps, lr=self.lr,
                lbfgs_steps=self.lbfgs_steps, objective=objective, progress=progress,
                on_epoch=None if on_epoch is None else log_step)
            fits[kernel], step = (theta, loss), step + steps
        self.kernel_ = min(fits, key=lambda k: fits[k][1])
        if len(fits) > 1:
            _log.info("gpr kernel: %s (−log marginal likelihood: %s)", self.kernel_,
                      ", ".join(f"{k} {loss:.4g}" for k, (_, loss) in fits.items()))
        per_input, self.outputscale_, self.noise_ = _gp_hyper.split_log_params(fits[self.kernel_][0])
        if self.kernel_ == "kinematic":
            self.offset_ = per_input                                       # (O, Dz) c_d
        else:
            self.lengthscale_ = per_input                                  # (O, Dz) ℓ_d
        return step

    def _settle_offsets(self, sums: tuple[torch.Tensor, torch.Tensor], ys: torch.Tensor) -> None:
        """The kinematic kernel's c_d (O, Dz): the hyper subset's or all 1 (a flat prior), the likelier on all the
        poses (their `_gp_trig.moments`, ys (O, N)), with s and σ² at their optimum there
        (`_gp_trig.refine_on_all_poses`)."""
        self.offset_, self.outputscale_, self.noise_ = _gp_trig.refine_on_all_poses(
            sums, ys, [self.offset_, torch.ones_like(self.offset_)], self.outputscale_,
            self.noise_, _gp_hyper.log_bounds(self.latent_dim, self.noise_floor)[-2:])

    def _standardized(self, y: torch.Tensor) -> torch.Tensor:
        """Targets in the fitted scaling. y (N, O) → (O, N)."""
        return ((y - self.y_mean_) / self.y_std_).T.contiguous()

    def condition(self, q, x, *, seed: int = 0) -> "GPRModel":
        """Re-condition on new data (q (N, Dz) rad, x (N, *out)) keeping the fitted hyper-parameters and target
        scaling: one Cholesky, no optimization (e.g. after a body change, or to compare training-set sizes)."""
        self._require_fitted()
        q, y = _gp_data.check_training_data(q, x, self.body, self.output_shape)        # (N, Dz), (N, O)
        if self.kernel_ == "rbf":                                                      # the kinematic one: all
            keep = _gp_data.random_subset(q.shape[0], self.max_points, torch.Generator().manual_seed(int(seed)))
            q, y = q[keep], y[keep]
        self._condition_unit(self.body.to_unit(q), self._standardized(y))
        return self

    def _condition_unit(self, u: torch.Tensor, ys: torch.Tensor, sums=None) -> None:
        """α = (K + σ²I)⁻¹ y by our own Cholesky, exact at any n (the kinematic kernel: its feature-form posterior,
        from `sums` = its ΦᵀΦ and Φᵀy where the fit has them already). u (n, Dz) in [-1, 1], ys (O, n) standardized."""
        self.train_u_ = u
        if self.kernel_ == "kinematic":
            self._trig = _gp_trig.TrigPosterior(self.body.from_unit(u), self.offset_, self.outputscale_, self.noise_,
                                                ys=ys, sums=sums)
            self.weights_ = self._trig.weights                                        # (O, 3^Dz)
            return
        self._factor = _gp_math.cholesky_factor(u, self.lengthscale_, self.outputscale_, self.noise_)   # (O, n, n)
        self.alpha_ = _gp_math.solve_weights(self._factor, ys)                        # (O, n)

    def _restored(self) -> None:
        if self.kernel_ == "kinematic":
            self._trig = _gp_trig.TrigPosterior(self.body.from_unit(self.train_u_), self.offset_, self.outputscale_,
                                                self.noise_, weights=self.weights_)

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        model = cls(body, modality, output_shape, **config)
        model.kernel_ = "kinematic" if "weights" in state else "rbf"                  # the fitted kernel's tensors
        _gp_data.restore_state(model, state, model.STATE_KEYS)
        model._restored()
        return model

    # ---- closed-form prediction ---------------------------------------------------------------------
    def _kernel(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        u = self.body.to_unit(z.to(torch.float64))                                    # (B, Dz)
        return u, _gp_math.rbf(u, self.train_u_, self.lengthscale_, self.outputscale_)  # (O, B, n)

    def _mean_and_jacobian(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Standardized mean (O, B) and its Jacobian in output units per rad (B, O, Dz)."""
        if self.kernel_ == "kinematic":
            mean, jac = self._trig.mean_and_jacobian(z.to(torch.float64))
            return mean, jac * self.y_std_[:, None]
        u, k = self._kernel(z)
        mean, jac_u = _gp_math.mean_and_jacobian(u, self.train_u_, k, self.alpha_, self.lengthscale_)
        return mean, jac_u * self.y_std_[:, None] * self.body.unit_per_rad(u)

    def _predict(self, z):
        if self.kernel_ == "kinematic":
            mean = self._trig.mean(z.to(torch.float64))                              # (O, B)
        else:
            mean = _gp_math.posterior_mean(self._kernel(z)[1], self.alpha_)          # (O, B)
        return (mean.T * self.y_std_ + self.y_mean_).reshape(z.shape[0], *self.output_shape)

    def _jacobian(self, z):
        return self._mean_and_jacobian(z)[1]                                          # (B, O, Dz) per rad

    def _vjp(self, z, v):
        # Jᵀv in float64 (the hooks compute in float64; the base class casts the result to z.dtype).
        return torch.einsum("bod,bo->bd", self._jacobian(z), v.reshape(v.shape[0], -1).to(torch.float64))

    def predict_with_jacobian(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """predict(z) and jacobian(z) sharing one kernel matrix. → (B, *out), (B, O, Dz)."""
        z = self._check_z(z)
        mean_u, jac = self._mean_and_jacobian(z)
        mean = mean_u.T * self.y_std_ + self.y_mean_                                 # (B, O)
        return mean.reshape(z.shape[0], *self.output_shape).to(z.dtype), jac.to(z.dtype)

    def _precision(self, z):
        """1 / (σ²_pred + σ²_noise) in output units⁻², diagonal. # (B, *out)"""
        if self.kernel_ == "kinematic":
            var = self._trig.variance(z.to(torch.float64))                           # (O, B) standardized
        else:
            var = _gp_math.posterior_variance(self._kernel(z)[1], self.factor, self.outputscale_)
        var_out = (var + self.noise_[:, None]) * self.y_std_[:, None].pow(2)          # (O, B) output units²
        return (1.0 / var_out).T.reshape(z.shape[0], *self.output_shape)

    @property
    def factor(self) -> torch.Tensor:
        """Cholesky factor of K + σ²I (O, n, n): kept after fit, recomputed on first use after load."""
        if self._factor is None:
            self._factor = _gp_math.cholesky_factor(self.train_u_, self.lengthscale_, self.outputscale_, self.noise_)
        return self._factor

    def to_gpytorch(self) -> BatchExactGP:
        """The fitted model as a gpytorch ExactGP in eval mode (for comparisons; inputs in [-1, 1], targets
        standardized). Its targets are rebuilt from α as y = (K + σ²I) α. RBF kernel only."""
        if self.kernel_ != "rbf":
            raise ValueError(must_be("the gpr kernel", "rbf for to_gpytorch", self.kernel_,
                                     'Fit with kernel="rbf" to compare with gpytorch.'))
        ys = (self.factor @ (self.factor.transpose(-1, -2) @ self.alpha_[..., None])).squeeze(-1)  # (O, n)
        floor = min(self.noise_floor, 0.5 * float(self.noise_.min()))
        gp = build_exact_gp(self.train_u_, ys, floor, self.lengthscale_[:, None, :],
                            self.outputscale_, self.noise_[:, None])
        gp.eval()
        return gp

    # ---- persistence --------------------------------------------------------------------------------
    def _config(self):
        return {"hyper_points": self.hyper_points, "max_points": self.max_points, "adam_steps": self.adam_steps,
                "lbfgs_steps": self.lbfgs_steps, "lr": self.lr, "noise_floor": self.noise_floor,
                "kernel": self.kernel}


def check_kernel(kernel: str, joints: int) -> None:
    """`kernel` is one of KERNELS, and "kinematic" has at most 7 joints (3^D features)."""
    if kernel not in KERNELS:
        raise ValueError(must_be("kernel", f"one of {KERNELS}", repr(kernel)))
    if kernel == "kinematic" and _gp_trig.feature_count(joints) > _gp_trig.MAX_FEATURES:
        raise ValueError(must_be('kernel "kinematic"', "used with at most 7 joints (3^D features)", f"{joints} joints",
                                 'Use kernel="rbf" or "auto" (which falls back to rbf).'))


def candidate_kernels(kernel: str, joints: int) -> tuple[str, ...]:
    """The kernels a fit tries: the one named, or for "auto" rbf and, up to 7 joints, kinematic."""
    if kernel != "auto":
        return (kernel,)
    return ("rbf", "kinematic") if _gp_trig.feature_count(joints) <= _gp_trig.MAX_FEATURES else ("rbf",)
