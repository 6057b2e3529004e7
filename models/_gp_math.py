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

import math
from collections.abc import Callable

import torch
from scipy.linalg import lapack
from threadpoolctl import ThreadpoolController

JITTER_TRIES = 7   # Cholesky attempts; each retry adds 10× more diagonal jitter (from 1e-10 · (s + σ²))
_BLAS_POOLS: ThreadpoolController | None = None   # found once, on first use (scipy's OpenBLAS is loaded by then)


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


def cholesky_factor(x: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor, noise: torch.Tensor,
                    kernel: torch.Tensor | None = None) -> torch.Tensor:
    """L with L Lᵀ = K(X, X) + σ² I, batched over kernels. noise (Ok,) → (Ok, n, n), zeros above the diagonal.

    kernel: K(X, X) (Ok, n, n) if already computed (it is copied, not changed). Exact (Cholesky) whatever n: unlike
    gpytorch's default, which switches to approximate CG solves above `max_cholesky_size` = 800 points.
    """
    if kernel is None:
        return factorize(rbf_train(x, lengthscale, outputscale), noise, outputscale + noise,
                         lambda o: rbf_train(x, lengthscale[o:o + 1], outputscale[o:o + 1])[0])
    return factorize(kernel.clone(), noise, outputscale + noise, lambda o: kernel[o])


def factorize(matrix: torch.Tensor, noise: torch.Tensor, scale: torch.Tensor,
              rebuild: Callable[[int], torch.Tensor]) -> torch.Tensor:
    """L with L Lᵀ = matrix + σ² I, IN PLACE, batched: matrix (Ok, n, n) symmetric, noise (Ok,) → the same tensor.

    Retries with growing diagonal jitter (from 1e-10 · scale, 10× more each time) only if the factorization fails;
    rebuild(o) gives output o's matrix (without the noise) again, since the failed attempt overwrote it.
    """
    matrix.diagonal(dim1=-2, dim2=-1).add_(noise[:, None])
    with blas_threads():
        for o in range(matrix.shape[0]):
            jitter = 1e-10 * float(scale[o])
            for _ in range(JITTER_TRIES):
                if _potrf_lower(matrix[o]):
                    break
                matrix[o] = rebuild(o)
                matrix[o].diagonal().add_(float(noise[o]) + jitter)
                jitter *= 10
            else:
                raise RuntimeError("K + σ²I is not positive definite even with jitter; the noise floor may be too "
                                   "low.")
    return matrix


def inverse_from_factor(factor: torch.Tensor) -> torch.Tensor:
    """(K + σ²I)⁻¹ from its Cholesky factor, which it OVERWRITES. factor (Ok, n, n) → the same tensor, symmetric."""
    with blas_threads():
        for o in range(factor.shape[0]):
            _, info = lapack.dpotri(factor[o].numpy().T, lower=0, overwrite_c=1)   # see _potrf_lower for the view
            if info != 0:
                raise RuntimeError(f"LAPACK dpotri failed (info {info}) on a factor that dpotrf accepted.")
    lower = factor.tril(-1)                                                 # dpotri fills one triangle only
    return factor.triu_().add_(lower).add_(lower.mT)


def _potrf_lower(k: torch.Tensor) -> bool:
    """Cholesky factor L of k (n, n) symmetric, contiguous float64, IN PLACE (zeros above); False if not PD.

    LAPACK in place through a numpy view: the row-major k is, read column-major, its own transpose (= k), whose
    upper factor U (Uᵀ U = k) is L read row-major. torch.linalg.cholesky copies its input first: with the page
    faults of that copy and of its result, 3 × 2000 points took 500 ms of CPU instead of 290 ms (1 thread).
    """
    _, info = lapack.dpotrf(k.numpy().T, lower=0, overwrite_a=1, clean=1)
    return info == 0


def blas_threads(threads: int | None = None):
    """A context running scipy's BLAS and LAPACK on `threads` threads (None: torch's count). OpenBLAS defaults to
    every core; on a shared 2-core machine its spinning threads cost more CPU time than the factorization itself."""
    global _BLAS_POOLS
    if _BLAS_POOLS is None:
        _BLAS_POOLS = ThreadpoolController()
    return _BLAS_POOLS.limit(limits=threads or torch.get_num_threads(), user_api="blas")


def solve_weights(factor: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """α = (K + σ²I)⁻¹ y from the Cholesky factor. factor (Ok, n, n), y (O, n) → (O, n)."""
    # Two triangular solves: torch.cholesky_solve took 73 ms instead of 5 ms for 3 × 2000 points (1 thread).
    half = torch.linalg.solve_triangular(factor, y[..., None], upper=False)             # (O, n, 1): L⁻¹ y
    return torch.linalg.solve_triangular(factor.mT, half, upper=True).squeeze(-1)     # (O, n)


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


def neg_mll_and_grad(x: torch.Tensor, y: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor,
                     noise: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact −log p(y | X) of O independent GPs and its gradient in LOG hyper-parameters, in closed form.

    x (m, D), y (O, m), lengthscale (O, D), outputscale (O,), noise (O,) → −MLL (O,) (total, not per point) and
    ∂(−MLL)/∂(log ℓ, log s, log σ²) (O, D + 2). Costs one Cholesky and one inverse per output (LAPACK dpotrf and
    dpotri in place: 5 ms for 500 points, 1 thread); autograd through the Cholesky (as gpytorch does) ~4× more.

        −MLL = ½ yᵀα + Σ log L_ii + (m/2) log 2π                               R&W (2006) Alg. 2.1, line 8
        ∂(−MLL)/∂θ = ½ tr(W ∂K/∂θ),  W = K⁻¹ − ααᵀ                              R&W eq. (5.9)
        ∂K/∂log s = K_f,  ∂K/∂log σ² = σ² I,  ∂K/∂log ℓ_d = K_f ⊙ (x_d − x_d')² / ℓ_d²
    """
    k_f = rbf_train(x, lengthscale, outputscale)                            # (O, m, m): K without the noise
    loss, alpha, k_inv = neg_mll_terms(k_f, y, noise, outputscale + noise)  # (O,), (O, m), (O, m, m)
    # W = P − Q with P = K⁻¹ and Q = ααᵀ; Q's terms come from K_f [α, α ⊙ X] (no (O, m, m) outer product).
    grad_noise = 0.5 * noise * (k_inv.diagonal(dim1=-2, dim2=-1).sum(-1) - alpha.pow(2).sum(-1))   # (O,)
    p_kf = k_inv.mul_(k_f)                                                  # (O, m, m): K⁻¹ ⊙ K_f, in place
    k_alpha = k_f @ torch.cat([alpha[..., None], alpha[..., None] * x], -1)  # (O, m, 1+D): K_f α, K_f (α ⊙ x_d)
    q_row = alpha * k_alpha[..., 0]                                         # (O, m): (ααᵀ ⊙ K_f) 1
    grad_scale = 0.5 * (p_kf.sum((-2, -1)) - q_row.sum(-1))                 # (O,)
    # ½ Σ_ij M_ij (x_id − x_jd)² = Σ_i x_id² (M 1)_i − x_dᵀ M x_d for symmetric M = W ⊙ K_f
    m_row = p_kf.sum(-1) - q_row                                            # (O, m): M 1
    m_x = p_kf @ x - alpha[..., None] * k_alpha[..., 1:]                    # (O, m, D): M X
    quad = m_row @ x.pow(2) - (m_x * x).sum(-2)                             # (O, D)
    grad_length = quad / lengthscale.pow(2)                                 # (O, D)
    return loss, torch.cat([grad_length, grad_scale[:, None], grad_noise[:, None]], -1)


def neg_mll_terms(k_f: torch.Tensor, y: torch.Tensor, noise: torch.Tensor, scale: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The exact −log p(y) of O GPs from their noise-free kernel matrices (any kernel), and what its gradient needs.

    k_f (O, m, m) (not changed), y (O, m), noise σ² (O,), scale (O,) the jitter's scale (`factorize`) →
    −MLL (O,) (R&W Alg. 2.1, line 8), α = (K_f + σ²I)⁻¹ y (O, m), (K_f + σ²I)⁻¹ (O, m, m) (in the factor's memory).
    """
    factor = factorize(k_f.clone(), noise, scale, lambda o: k_f[o])        # (O, m, m)
    alpha = solve_weights(factor, y)                                        # (O, m)
    log_det = factor.diagonal(dim1=-2, dim2=-1).log().sum(-1)              # (O,): ½ log |K|
    loss = 0.5 * (y * alpha).sum(-1) + log_det + 0.5 * y.shape[-1] * math.log(2 * math.pi)
    return loss, alpha, inverse_from_factor(factor)
