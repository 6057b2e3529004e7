"""The closed-form math of `svgp` (see its module doc for the formulas): the batched ARD RBF kernel, the jittered
Cholesky factor of K(U, U), k-means inducing points, and the collapsed (Titsias 2009) posterior on all poses in
chunks. Plain tensors in float64, one independent GP per output; no gpytorch.
"""

from __future__ import annotations

import torch

from bodyschema.models import _gp_data

JITTER = 1e-12         # first relative jitter on K_uu in the closed form (× 10 per failed try, chol_uu)
JITTER_TRIES = 7
CHUNK = 4096           # poses per block of the closed-form pass: an (M, CHUNK) kernel block per output
KMEANS_ITERS = 10      # Lloyd's iterations of the inducing-point initialization


def rbf(u: torch.Tensor, x: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor) -> torch.Tensor:
    """ARD RBF kernel, one input set per output. u (B, D) or (O, B, D), x (O, M, D), lengthscale (O, D),
    outputscale (O,) → (O, B, M). The expanded square in one matmul (as `_gp_math.rbf`), then one exp."""
    us = u / lengthscale[:, None, :]                                        # (O, B, D)
    xs = x / lengthscale[:, None, :]                                        # (O, M, D)
    a = torch.cat([us, -0.5 * us.pow(2).sum(-1, keepdim=True), torch.ones_like(us[..., :1])], -1)   # (O, B, D+2)
    b = torch.cat([xs, torch.ones_like(xs[..., :1]),
                   outputscale.log()[:, None, None] - 0.5 * xs.pow(2).sum(-1, keepdim=True)], -1)   # (O, M, D+2)
    return (a @ b.transpose(-1, -2)).exp()                                  # (O, B, M)


def chol_uu(inducing: torch.Tensor, lengthscale: torch.Tensor, outputscale: torch.Tensor) -> torch.Tensor:
    """L with L Lᵀ = K(U, U) + j·s·I, j the smallest of 1e-12, 1e-11, … that factors (per output, the same j for
    the same inputs: a loaded model gets its L back). A fixed 1e-8 cost 5e-5 m against the exact posterior with
    U = X on the toy arm; 1e-12, 7e-9 m. inducing (O, M, D) → (O, M, M)."""
    k = rbf(inducing, inducing, lengthscale, outputscale)                   # (O, M, M)
    k = 0.5 * (k + k.mT)
    k.diagonal(dim1=-2, dim2=-1).copy_(outputscale[:, None].expand(-1, k.shape[-1]))
    jitter = torch.full_like(outputscale, JITTER)                           # (O,)
    for _ in range(JITTER_TRIES):
        factor, info = torch.linalg.cholesky_ex(k + torch.diag_embed((jitter * outputscale)[:, None].expand(
            -1, k.shape[-1])))
        if not bool((info > 0).any()):
            return factor
        jitter = torch.where(info > 0, jitter * 10, jitter)
    raise RuntimeError("K(U, U) is not positive definite even with jitter: inducing points may coincide.")


def kmeans(u: torch.Tensor, m: int, gen: torch.Generator) -> torch.Tensor:
    """m k-means centres of u (N, D) by Lloyd's iterations from a seeded random subset (an empty cluster keeps its
    centre). → (m, D)"""
    centres = u[_gp_data.random_subset(u.shape[0], m, gen)].clone()               # (m, D)
    for _ in range(KMEANS_ITERS):
        sums, counts = torch.zeros_like(centres), torch.zeros(m, dtype=u.dtype)
        for block in u.split(CHUNK):
            nearest = torch.cdist(block, centres).argmin(-1)                        # (c,)
            sums.index_add_(0, nearest, block)
            counts.index_add_(0, nearest, torch.ones_like(nearest, dtype=u.dtype))
        filled = counts > 0
        centres[filled] = sums[filled] / counts[filled, None]
    return centres


def collapsed_posterior(u: torch.Tensor, ys: torch.Tensor, inducing: torch.Tensor, lengthscale: torch.Tensor,
                        outputscale: torch.Tensor, noise: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The optimal q(u) of Titsias (2009) on all samples, as (α (O, M), T (O, M, M)) of the module doc.
    u (N, D), ys (O, N), inducing (O, M, D). One pass over the samples in CHUNK blocks: O(N·M²) per output."""
    chol = chol_uu(inducing, lengthscale, outputscale)                              # (O, M, M)
    n_out, m = inducing.shape[:2]
    gram = torch.zeros(n_out, m, m, dtype=u.dtype, device=u.device)                 # V Vᵀ
    vy = torch.zeros(n_out, m, 1, dtype=u.dtype, device=u.device)                   # V y
    for start in range(0, u.shape[0], CHUNK):
        block = slice(start, start + CHUNK)
        k = rbf(u[block], inducing, lengthscale, outputscale)                      # (O, c, M)
        v = torch.linalg.solve_triangular(chol, k.mT, upper=False)                 # (O, M, c)
        gram.baddbmm_(v, v.mT)
        vy.baddbmm_(v, ys[:, block, None])
    gram.diagonal(dim1=-2, dim2=-1).add_(noise[:, None])                            # B = σ²I + V Vᵀ
    chol_b = torch.linalg.cholesky(gram)                                            # (O, M, M)
    half = torch.linalg.solve_triangular(chol_b, vy, upper=False)                  # L_B⁻¹ V y
    alpha = torch.linalg.solve_triangular(chol.mT, torch.linalg.solve_triangular(chol_b.mT, half, upper=True),
                                          upper=True).squeeze(-1)                   # (O, M): L⁻ᵀ B⁻¹ V y
    eye = torch.eye(m, dtype=u.dtype, device=u.device).expand(n_out, m, m)
    factor = noise.sqrt()[:, None, None] * torch.linalg.solve_triangular(chol_b, eye, upper=False)   # σ L_B⁻¹
    return alpha, factor
