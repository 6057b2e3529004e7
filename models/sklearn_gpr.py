"""`sklearn_gpr`: scikit-learn's GaussianProcessRegressor as a sensory model, the baseline of `gpr`.

Kernel c · RBF(ℓ ARD) + White(σ²) with `normalize_y=True`; scikit-learn fits ONE kernel shared by all outputs
(its native multi-output GP, the likelihood summed over outputs), where `gpr` fits one kernel per output.
Hyper-parameters maximize the log marginal likelihood (L-BFGS-B) on a seeded random subset of `hyper_points`
samples, then the regressor is conditioned on all kept samples (`optimizer=None`: one Cholesky).

predict and precision are scikit-learn's own `predict(return_std=True)` (its std includes the white noise, so
precision = 1 / std²); the Jacobian is closed form from `alpha_` and the fitted kernel (`_gp_math.py`).

Saved state: kernel hyper-parameters, scaled training inputs and the training targets, as tensors (no pickle).
The regressor is rebuilt by the same conditioning step that `fit` ends with, through scikit-learn's public
API only, so outputs are bit-identical after a reload (alpha_ alone would not rebuild `L_`, which `predict`
needs for the std, without setting scikit-learn's private attributes).
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Callable

import numpy as np
import scipy.optimize
import torch
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
from tqdm.auto import tqdm

from bodyschema.errors import must_be
from bodyschema.models import _gp_data, _gp_math
from bodyschema.models.capabilities import GPMemory
from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.scaling import BodySpec

STATE_KEYS = ("train_u", "train_y", "lengthscale", "outputscale", "noise")
JITTER = 1e-10   # GaussianProcessRegressor(alpha=...): added to the diagonal on top of the white noise


def make_kernel(latent_dim: int, noise_floor: float, lengthscale=0.5, outputscale=1.0, noise=1e-3):
    """c · RBF(ℓ, ARD) + White(σ²) with bounds wide enough for standardized targets."""
    return (ConstantKernel(outputscale, (1e-6, 1e4))
            * RBF(np.broadcast_to(np.asarray(lengthscale, dtype=np.float64), (latent_dim,)).copy(), (1e-3, 1e3))
            + WhiteKernel(max(noise, noise_floor), (noise_floor, 1.0)))


@register_kind
class SklearnGPRModel(_gp_data.SavedGPState, BaseSensoryModel):
    """scikit-learn GP sensory model, kind "sklearn-gpr". `__init__` stores hyper-parameters only."""

    STATE_KEYS = STATE_KEYS
    kind = "sklearn-gpr"
    precision_varies = True      # 1 / predictive std² at z
    onnx_hint = "scikit-learn computes its mean in numpy: train kind 'gpr' for an exportable GP"
    # measured peak (training/guards.py): its gradient is (m, m, Dz + 2); one kernel serves all outputs
    gp_memory = GPMemory(fit_copies=14.0, condition_copies=3.5, per_output=False)

    def __init__(self, body: BodySpec, modality: str, output_shape: tuple[int, ...], *,
                 hyper_points: int = 500,     # LML fitted on this many samples (sklearn's gradient is O(m²·D) memory)
                 max_points: int = 5000,      # conditioned on at most this many (seeded random subset beyond)
                 max_iter: int = 500,         # L-BFGS-B iterations
                 noise_floor: float = 1e-7):  # lower bound of the white noise on standardized targets (as `gpr`)
        super().__init__(body, modality, output_shape)
        _gp_data.check_gp_hyper(hyper_points, max_points, noise_floor)
        # 0 keeps the initial kernel; scipy quietly runs 1 iteration for a negative count
        if isinstance(max_iter, bool) or not isinstance(max_iter, numbers.Integral) or max_iter < 0:
            raise ValueError(must_be("max_iter", "an integer ≥ 0 (L-BFGS-B iterations)", max_iter))
        self.hyper_points, self.max_points = int(hyper_points), int(max_points)
        self.max_iter, self.noise_floor = int(max_iter), float(noise_floor)

    @property
    def is_fitted(self) -> bool:
        return hasattr(self, "regressor_")

    # ---- fitting ------------------------------------------------------------------------------------
    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch: Callable[[int, dict[str, float]], None] | None = None,
            progress: bool = False) -> "SklearnGPRModel":
        """Fit on joint angles q (N, Dz) rad and observations x (N, *output_shape) (numpy or torch). Returns self.

        seed: the random subsets. val = (q_val, x_val): evaluated once after fitting. on_epoch(step, metrics):
        every log-marginal-likelihood evaluation {"train_neg_lml"} (total, scikit-learn's objective), then
        {"val_mean_error", "val_rmse"} (output units: mean per-sample Euclidean error, RMSE over all
        output elements, as training.scoring.score) when val is given.
        """
        u, y, val, gen = _gp_data.training_subset(self, q, x, val, seed)              # (n, Dz), (n, O)
        sub = _gp_data.random_subset(u.shape[0], self.hyper_points, gen)

        bar = tqdm(total=None, desc="sklearn_gpr hyper-parameters", disable=not progress)
        step = 0

        def optimizer(obj_func, theta0, bounds):
            def logged(theta):
                nonlocal step
                value, grad = obj_func(theta)
                step += 1
                bar.update(1)
                if on_epoch is not None:
                    on_epoch(step, {"train_neg_lml": float(value)})
                return value, grad
            res = scipy.optimize.minimize(logged, theta0, method="L-BFGS-B", jac=True, bounds=bounds,
                                          options={"maxiter": self.max_iter})
            return res.x, res.fun

        hyper = GaussianProcessRegressor(make_kernel(self.latent_dim, self.noise_floor), alpha=JITTER,
                                         optimizer=optimizer, normalize_y=True, random_state=int(seed))
        with warnings.catch_warnings():
            # The white noise reaching its floor is expected on noise-free data (the floor is the design).
            warnings.filterwarnings("ignore", message=".*noise_level is close to the specified lower bound",
                                    category=ConvergenceWarning)
            hyper.fit(u[sub].numpy(), y[sub].numpy())
        bar.close()
        kernel = hyper.kernel_
        self.lengthscale_ = torch.as_tensor(np.atleast_1d(kernel.k1.k2.length_scale), dtype=torch.float64)  # (Dz,)
        self.outputscale_ = torch.tensor([kernel.k1.k1.constant_value], dtype=torch.float64)                # (1,)
        self.noise_ = torch.tensor([kernel.k2.noise_level], dtype=torch.float64)                           # (1,)
        self.train_u_, self.train_y_ = u, y
        self._condition()
        if val is not None and on_epoch is not None:
            diff = self._predict(val[0]).reshape(val[1].shape) - val[1]                   # (Nv, O)
            on_epoch(step, {"val_mean_error": float(diff.norm(dim=-1).mean()),
                            "val_rmse": float(diff.pow(2).mean().sqrt())})
        return self

    def _condition(self) -> None:
        """Condition a fixed-kernel regressor on all training samples (one Cholesky, no optimization)."""
        kernel = make_kernel(self.latent_dim, self.noise_floor, self.lengthscale_.numpy(),
                             float(self.outputscale_[0]), float(self.noise_[0]))
        self.regressor_ = GaussianProcessRegressor(kernel, alpha=JITTER, optimizer=None, normalize_y=True)
        self.regressor_.fit(self.train_u_.numpy(), self.train_y_.numpy())

    # ---- prediction ---------------------------------------------------------------------------------
    def _unit(self, z: torch.Tensor) -> torch.Tensor:
        return self.body.to_unit(z.to(torch.float64))                                 # (B, Dz)

    def _predict(self, z):
        mean = self.regressor_.predict(self._unit(z).numpy())                        # (B, O) or (B,)
        return torch.from_numpy(np.asarray(mean)).reshape(z.shape[0], *self.output_shape)

    def _jacobian(self, z):
        u = self._unit(z)
        reg = self.regressor_
        k = _gp_math.rbf(u, self.train_u_, self.lengthscale_[None], self.outputscale_)  # (1, B, n)
        alpha = torch.from_numpy(reg.alpha_).reshape(self.train_u_.shape[0], -1).T      # (O, n)
        _, jac_u = _gp_math.mean_and_jacobian(u, self.train_u_, k, alpha, self.lengthscale_[None])   # (B, O, Dz)
        # normalize_y's per-output scale (private attribute; a change would fail the finite-difference test)
        y_std = torch.as_tensor(np.atleast_1d(reg._y_train_std), dtype=torch.float64)  # (O,)
        return jac_u * y_std[:, None] * self.body.unit_per_rad(u)                     # (B, O, Dz) per rad

    def _vjp(self, z, v):
        # Jᵀv in float64 (the hooks compute in float64; the base class casts the result to z.dtype).
        return torch.einsum("bod,bo->bd", self._jacobian(z), v.reshape(v.shape[0], -1).to(torch.float64))

    def _precision(self, z):
        """1 / std² from scikit-learn's predictive std (latent + white noise), output units⁻². # (B, *out)"""
        _, std = self.regressor_.predict(self._unit(z).numpy(), return_std=True)     # (B, O) or (B,)
        return torch.from_numpy(1.0 / np.asarray(std) ** 2).reshape(z.shape[0], *self.output_shape)

    def _precision_vjp(self, z, v):
        # sklearn computes outside torch: central differences of Π, step 2e-4 of each joint's range (Π cancels digits).
        z = z.to(torch.float64)
        steps = 2e-4 * (torch.tensor(self.body.q_high) - torch.tensor(self.body.q_low)).to(torch.float64)   # (Dz,) rad
        v = v.reshape(v.shape[0], -1).to(torch.float64)                                # (B, O)
        out = torch.empty_like(z)
        for d, h in enumerate(steps):
            shift = torch.zeros_like(z)
            shift[:, d] = h
            dpi = (self._precision(z + shift) - self._precision(z - shift)).reshape(v.shape) / (2 * h)   # (B, O)
            out[:, d] = (dpi * v).sum(-1)
        return out

    # ---- persistence --------------------------------------------------------------------------------
    def _config(self):
        return {"hyper_points": self.hyper_points, "max_points": self.max_points, "max_iter": self.max_iter,
                "noise_floor": self.noise_floor}

    def _restored(self) -> None:
        self._condition()
