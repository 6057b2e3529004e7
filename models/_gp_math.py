"""Closed-form math of an exact GP with an ARD RBF kernel, shared by the `gpr` and `sklearn_gpr` models.

Everything here is in the model's internal units: inputs u in [-1, 1] (scaled joint angles), outputs standardized.
A kernel may be batched over outputs (one hyper-parameter set per output, `gpr`) or shared (`sklearn_gpr`):
`Ok` below is O (independent kernels) or 1 (one kernel broadcast over the O outputs).

    k(u, x) = s · exp(−½ Σ_d (u_d − x_d)² / ℓ_d²)                        Rasmussen & Williams (2006) eq. (5.1)
    m(u)    = Σ_i α_i k(u, x_i),  α = (K + σ²I)⁻¹ y                       R&W Alg. 2.1, lines 2–4
    ∂m/∂u_d = −Σ_i α_i k(u, x_i)(u_d − x_id)/ℓ_d²
            = −(u_d Σ_i w_i − Σ_i w_i x_id)/ℓ_d²,  w = α ⊙ k(u, X)        one matmul, no (B, n, D) tensor;
                                                                      Σ_i w_i = m(u) comes with it
    v(u)    = s − ‖L⁻¹ k(X, u)‖²,  L Lᵀ = K + σ²I                          R&W Alg. 2.1, lines 5–6
"""

from __future__ import annotations

import torch

JITTER_TRIES = 6   # Cholesky retries, each adding 10× more diagonal jitter (starting at 1e-10 · mean diag)


def rbf(u: torch.Tensor, x: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor) -> torch.Tensor:
    """ARD RBF kernel matrix. u (B, D), x (n, D), lengthscale (Ok, D), outputscale (Ok,) → (Ok, B, n)."""
    us = u[None] / lengthscale[:, None, :]                                  # (Ok, B, D)
    xs = x[None] / lengthscale[:, None, :]                                  # (Ok, n, D)
    # log k = log s − ½|u|² + u·x − ½|x|² (the expanded square, as gpytorch's sq_dist): one matmul of
    # augmented inputs, then one in-place exp — no (Ok, B, n) temporaries for the broadcast sums.
    a = torch.cat([us, -0.5 * us.pow(2).sum(-1, keepdim=True), torch.ones_like(us[..., :1])], -1)   # (Ok, B, D+2)
    b = torch.cat([xs, torch.ones_like(xs[..., :1]),
                   outputscale.log()[:, None, None] - 0.5 * xs.pow(2).sum(-1, keepdim=True)], -1)   # (Ok, n, D+2)
    return (a @ b.transpose(-1, -2)).exp_()                                 # (Ok, B, n)


def rbf_train(x: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor) -> torch.Tensor:
    """K(X, X) with an exact zero distance on the diagonal. x (n, D) → (Ok, n, n)."""
    k = rbf(x, x, lengthscale, outputscale)                                 # (Ok, n, n)
    k.diagonal(dim1=-2, dim2=-1).copy_(outputscale[:, None].expand(-1, x.shape[0]))
    return k


def cholesky_factor(x: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor,
                    noise: torch.Tensor) -> torch.Tensor:
    """L with L Lᵀ = K(X, X) + σ² I, batched over kernels. noise (Ok,) → (Ok, n, n).

    Exact (Cholesky) whatever n: unlike gpytorch's default, which switches to approximate CG solves above
    `max_cholesky_size` = 800 points. Retries with growing jitter only if the factorization fails.
    """
    k = rbf_train(x, lengthscale, outputscale)                              # (Ok, n, n)
    k.diagonal(dim1=-2, dim2=-1).add_(noise[:, None])
    factor, info = torch.linalg.cholesky_ex(k)
    jitter = 1e-10 * k.diagonal(dim1=-2, dim2=-1).mean()
    for _ in range(JITTER_TRIES):
        if not bool(info.any()):
            return factor
        k.diagonal(dim1=-2, dim2=-1).add_(jitter)
        factor, info = torch.linalg.cholesky_ex(k)
        jitter = jitter * 10
    if bool(info.any()):
        raise RuntimeError("K + σ²I is not positive definite even with jitter; the noise floor may be too low.")
    return factor


def solve_weights(factor: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """α = (K + σ²I)⁻¹ y from the Cholesky factor. factor (Ok, n, n), y (O, n) → (O, n)."""
    return torch.cholesky_solve(y[..., None], factor).squeeze(-1)          # (O, n)


def posterior_mean(k: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """m = k α. k (Ok, B, n), alpha (O, n) → (O, B)."""
    return (k @ alpha[:, :, None]).squeeze(-1)                              # (O, B); Ok = 1 broadcasts


def mean_and_jacobian(u: torch.Tensor, x: torch.Tensor, k: torch.Tensor, alpha: torch.Tensor,
                      lengthscale: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """m and ∂m/∂u in closed form from one kernel matrix.
    u (B, D), x (n, D), k (Ok, B, n), alpha (O, n), lengthscale (Ok, D) → m (O, B), ∂m/∂u (B, O, D)."""
    # Σ_i w_i [x_i, 1] with w = α ⊙ k, computed as k @ (α ⊙ [X, 1]): no pass over an (O, B, n) product.
    x1 = torch.cat([x, torch.ones_like(x[:, :1])], -1)                      # (n, D+1)
    moments = k @ (alpha[:, :, None] * x1)                                  # (O, B, D+1): Σ w x, Σ w
    mean = moments[..., -1]                                                 # (O, B): Σ_i α_i k_i = m
    jac = -(u[None] * mean[..., None] - moments[..., :-1]) / lengthscale.pow(2)[:, None, :]   # (O, B, D)
    return mean, jac.transpose(0, 1)                                        # (O, B), (B, O, D)


def posterior_variance(k: torch.Tensor, factor: torch.Tensor, outputscale: torch.Tensor) -> torch.Tensor:
    """Latent predictive variance s − ‖L⁻¹ kᵀ‖², clamped at 0. k (Ok, B, n), factor (Ok, n, n) → (Ok, B)."""
    v = torch.linalg.solve_triangular(factor, k.transpose(-1, -2), upper=False)   # (Ok, n, B)
    return (outputscale[:, None] - v.pow(2).sum(-2)).clamp_min(0.0)
