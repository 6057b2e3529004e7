"""The `gpr` kinematic kernel: exact for a point carried by a chain of revolute joints.

    k(q, q') = s · Π_d (c_d + cos(q_d − q'_d)) / (1 + c_d)              q in rad, c_d > 0, s > 0
             = φ(q)ᵀ diag(λ) φ(q'),   φ(q) = ⊗_d (1, cos q_d, sin q_d)   (P = 3^D features)
                                      λ = s · ⊗_d (c_d, 1, 1) / (1 + c_d)

Why this kernel: a point fixed on the last link, seen in the base frame, is p(q) = T_1(q_1) ⋯ T_D(q_D) p_D, and each
rotation's entries are affine in (cos q_d, sin q_d) (Rodrigues' formula), so every coordinate of p is a multilinear
polynomial in them: p lies exactly in the span of φ. A GP with this kernel is Bayesian linear regression on φ and
interpolates the forward kinematics from about P poses (measured, `train gpr` on 3 000-pose stores: 0.00004 mm
held-out on a UR5, 0.0013 mm on a 7-joint Panda URDF, where the RBF kernel is 83 and 100 mm off over the same full
joint ranges). c_d weighs joint d's
constant term against its first harmonic; a large c_d switches the joint off (as a long RBF length scale does).
Not exact for camera pixels (a ratio of such polynomials) nor a prismatic joint: the `auto` kernel choice compares
the marginal likelihoods of both kernels (`models/gpr.py`).

The hyper-parameters are fitted in kernel form on the hyper subset (m × m matrices, `neg_mll_and_grad`), then
settled on every pose (`refine_on_all_poses`); the posterior is computed in feature form on every pose (P × P, any
n, ΦᵀΦ summed in blocks):
    ψ = √λ ⊙ φ,   A = Ψᵀ Ψ + σ² I = L Lᵀ,   v = √λ ⊙ A⁻¹ Ψᵀ y                  (Bishop 2006, eqs. 3.53–3.54)
    m(q) = φ(q) · v,   ∂m/∂q_d = ∂φ/∂q_d · v,   var(q) = σ² ‖L⁻¹ ψ(q)‖²              (eqs. 3.58–3.59)
"""

from __future__ import annotations

import math

import numpy as np
import scipy.optimize
import torch

from bodyschema.models import _gp_math

MAX_FEATURES = 3 ** 7      # 7 joints: a 2187² system per output (~1 s); 8 would be 6561² (~30 s, 340 MB each)
CHUNK = 8192               # poses per block of Φ while summing ΦᵀΦ: 8192 × 2187 float64 = 143 MB at 7 joints


def feature_count(joints: int) -> int:
    """P = 3^D: (1, cos, sin) per joint, all products."""
    return 3 ** joints


def _basis(q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per joint (1, cos q, sin q) and its derivative in q. q (B, D) rad → (B, D, 3), (B, D, 3)."""
    cos, sin = q.cos(), q.sin()
    return (torch.stack([torch.ones_like(q), cos, sin], -1),
            torch.stack([torch.zeros_like(q), -sin, cos], -1))


def _kron(factors: list[torch.Tensor]) -> torch.Tensor:
    """Row-wise Kronecker product of (B, 3) factors, the first one slowest. → (B, 3^len)."""
    out = factors[0]
    for f in factors[1:]:
        out = (out[:, :, None] * f[:, None, :]).reshape(out.shape[0], -1)
    return out


def features(q: torch.Tensor) -> torch.Tensor:
    """φ(q). q (B, D) rad → (B, 3^D)."""
    value, _ = _basis(q)
    return _kron(list(value.unbind(1)))


def features_and_derivatives(q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """φ(q) and ∂φ/∂q_d (joint d's factor replaced by its derivative). q (B, D) → (B, P), (B, D, P)."""
    value, slope = _basis(q)
    values = list(value.unbind(1))
    derivatives = [_kron(values[:d] + [slope[:, d]] + values[d + 1:]) for d in range(q.shape[1])]
    return _kron(values), torch.stack(derivatives, 1)


def moments(q: torch.Tensor, ys: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor | None]:
    """ΦᵀΦ (P, P) and Φᵀy per output (O, P) over any number of poses, in blocks of CHUNK (memory O(CHUNK·P + P²),
    not O(n·P)). q (n, D) rad, ys (O, n) or None."""
    p = feature_count(q.shape[1])
    gram = torch.zeros(p, p, dtype=torch.float64)
    phi_y = None if ys is None else torch.zeros(ys.shape[0], p, dtype=torch.float64)
    for i in range(0, q.shape[0], CHUNK):
        phi = features(q[i:i + CHUNK])                                      # (≤ CHUNK, P)
        gram += phi.T @ phi
        if ys is not None:
            phi_y += ys[:, i:i + CHUNK] @ phi
    return gram, phi_y


def prior_weights(offset: torch.Tensor, outputscale: torch.Tensor) -> torch.Tensor:
    """λ = s ⊗_d (c_d, 1, 1) / (1 + c_d). offset c (O, D), outputscale s (O,) → (O, P)."""
    per_joint = torch.stack([offset, torch.ones_like(offset), torch.ones_like(offset)], -1) / (1 + offset)[..., None]
    out = outputscale[:, None]
    for d in range(offset.shape[1]):
        out = (out[:, :, None] * per_joint[:, d, None, :]).reshape(out.shape[0], -1)
    return out                                                               # (O, P)


def neg_mll_and_grad(q: torch.Tensor, y: torch.Tensor, offset: torch.Tensor, outputscale: torch.Tensor,
                     noise: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact −log p(y | q) of O GPs with the kinematic kernel, and its gradient in log (c (D), s, σ²).

    q (m, D) rad, y (O, m), offset (O, D), outputscale (O,), noise (O,) → (O,), (O, D + 2). Kernel form, as
    `_gp_math.neg_mll_and_grad` (R&W Alg. 2.1, eq. 5.9):  ∂(−MLL)/∂θ = ½ Σ_ij W_ij ∂K_ij/∂θ,  W = K⁻¹ − ααᵀ, with
        ∂K/∂log s = K_f,  ∂K/∂log σ² = σ² I,  ∂K/∂log c_d = s Π_{e≠d} f_e · c_d (1 − cos Δ_d) / (1 + c_d)²,
        f_d = (c_d + cos Δ_d) / (1 + c_d),  Δ_d = q_d − q'_d.
    The product over the other joints is formed directly (not K / f_d: f_d may be 0).
    """
    cos_delta = torch.cos(q.T[:, :, None] - q.T[:, None, :])                # (D, m, m)
    c = offset[:, :, None, None]                                            # (O, D, 1, 1)
    f = (c + cos_delta) / (1 + c)                                           # (O, D, m, m)
    s = outputscale[:, None, None]
    k_f = s * f.prod(1)                                                     # (O, m, m)
    loss, alpha, k_inv = _gp_math.neg_mll_terms(k_f, y, noise, outputscale + noise)   # (O,), (O, m), (O, m, m)
    w = k_inv.sub_(alpha[:, :, None] * alpha[:, None, :])                   # (O, m, m): W
    grad_scale = 0.5 * (w * k_f).sum((-2, -1))                              # (O,)
    grad_noise = 0.5 * noise * w.diagonal(dim1=-2, dim2=-1).sum(-1)         # (O,)
    grad_offset = []
    for d in range(q.shape[1]):
        others = s * f[:, [e for e in range(q.shape[1]) if e != d]].prod(1)  # (O, m, m)
        slope = c[:, d] * (1 - cos_delta[d]) / (1 + c[:, d]) ** 2           # (O, m, m)
        grad_offset.append(0.5 * (w * others * slope).sum((-2, -1)))
    return loss, torch.cat([torch.stack(grad_offset, -1), grad_scale[:, None], grad_noise[:, None]], -1)


class TrigPosterior:
    """The posterior of O kinematic-kernel GPs conditioned on (q (n, D) rad, ys (O, n) standardized targets).

    weights (O, P): m(q) = φ(q) · v. The Cholesky factor of A (O, P, P), needed only for the variance, is formed
    on first use from the kept poses (after a load too). ΦᵀΦ is summed in blocks: any number of poses fits in memory.
    """

    def __init__(self, q: torch.Tensor, offset: torch.Tensor, outputscale: torch.Tensor, noise: torch.Tensor,
                 ys: torch.Tensor | None = None, weights: torch.Tensor | None = None,
                 sums: tuple[torch.Tensor, torch.Tensor] | None = None):
        self.q, self.noise = q, noise
        self.root = prior_weights(offset, outputscale).sqrt()               # (O, P): √λ
        self._factor, self._gram = None, None
        if weights is None:                     # sums: `moments(q, ys)` when the caller has them already
            self._gram, phi_y = sums if sums is not None else moments(q, ys)
            psi_y = self.root * phi_y                                       # (O, P): Ψᵀ y = √λ ⊙ Φᵀ y
            half = torch.linalg.solve_triangular(self.factor, psi_y[..., None], upper=False)
            weights = self.root * torch.linalg.solve_triangular(self.factor.mT, half, upper=True).squeeze(-1)
        self.weights = weights                                              # (O, P)

    @property
    def factor(self) -> torch.Tensor:
        """L with L Lᵀ = diag(√λ) ΦᵀΦ diag(√λ) + σ² I. # (O, P, P)"""
        if self._factor is None:
            gram = self._gram if self._gram is not None else moments(self.q)[0]   # (P, P)
            self._gram = None                                               # needed once: free its P² floats
            scaled = self.root[:, :, None] * gram[None] * self.root[:, None, :]   # (O, P, P)
            scale = scaled.diagonal(dim1=-2, dim2=-1).mean(-1) + self.noise
            self._factor = _gp_math.factorize(
                scaled, self.noise, scale, lambda o: self.root[o, :, None] * gram * self.root[o, None, :])
        return self._factor

    def mean(self, q: torch.Tensor) -> torch.Tensor:
        """m(q). q (B, D) rad → (O, B)."""
        return self.weights @ features(q).T

    def mean_and_jacobian(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """m(q) and ∂m/∂q per rad. q (B, D) → (O, B), (B, O, D)."""
        phi, slope = features_and_derivatives(q)                            # (B, P), (B, D, P)
        return self.weights @ phi.T, (slope @ self.weights.T).transpose(1, 2)

    def variance(self, q: torch.Tensor) -> torch.Tensor:
        """Latent predictive variance σ² ‖L⁻¹ ψ(q)‖². q (B, D) → (O, B)."""
        psi = self.root[:, :, None] * features(q).T[None]                   # (O, P, B)
        v = torch.linalg.solve_triangular(self.factor, psi, upper=False)    # (O, P, B)
        return self.noise[:, None] * v.pow(2).sum(-2)


def refine_on_all_poses(sums: tuple[torch.Tensor, torch.Tensor], ys: torch.Tensor, offsets: list[torch.Tensor],
                        outputscale: torch.Tensor, noise: torch.Tensor, bounds: np.ndarray
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per output, the likeliest of the candidate `offsets` on ALL n poses, with s and σ² at its optimum there.

    Why: the offsets c come from the hyper subset, a few hundred poses, fewer than the 3^D features, where the
    likelihood can switch a joint off and call the rest noise (TALOS's left arm, y: c_5 = 1e5, σ² = 0.02
    standardized, 49 mm held-out, while the same features fit its 3 000 poses to 1e-5 mm). On all n, for one c,
    with M = diag(√λ₀) ΦᵀΦ diag(√λ₀) = V diag(e) Vᵀ (λ₀: λ at s = 1), b = Vᵀ (√λ₀ ⊙ Φᵀ y), d_p = σ² + s e_p
    (Woodbury and the determinant lemma on K = s Ψ₀Ψ₀ᵀ + σ² I):
        −MLL = ½ (yᵀy − s Σ b²/d) / σ² + ½ ((n − P) log σ² + Σ log d) + (n/2) log 2π
    costs O(P) per evaluation after one eigendecomposition per output and candidate, so s and σ² are optimized
    there; c is not (its gradient would need an eigendecomposition per step).
    sums: `moments(q, ys)` of the n poses (ΦᵀΦ (P, P), Φᵀy (O, P)), ys (O, n), offsets: candidates (O, D) each,
    outputscale and noise (O,) the starts, bounds (2, 2) rows (log s, log σ²) [low, high] → offset (O, D), s (O,),
    σ² (O,).
    """
    gram, phi_y = sums
    n = ys.shape[1]
    best = [(math.inf, None)] * ys.shape[0]
    for offset in offsets:
        root = prior_weights(offset, torch.ones_like(outputscale)).sqrt()   # (O, P)
        for o in range(ys.shape[0]):
            e, v = torch.linalg.eigh(root[o, :, None] * gram * root[o, None, :])
            objective = _scale_noise_mll(e.clamp_min(0).numpy(), (v.T @ (root[o] * phi_y[o])).pow(2).numpy(),
                                         float(ys[o] @ ys[o]), n)
            start = np.log([float(outputscale[o]), float(noise[o])])
            result = scipy.optimize.minimize(objective, start, jac=True, method="L-BFGS-B", bounds=bounds)
            if result.fun < best[o][0]:
                best[o] = (result.fun, (offset[o], *np.exp(result.x)))
    chosen = [params for _, params in best]
    return (torch.stack([c for c, _, _ in chosen]), torch.tensor([s for _, s, _ in chosen], dtype=torch.float64),
            torch.tensor([s2 for _, _, s2 in chosen], dtype=torch.float64))


def _scale_noise_mll(e: np.ndarray, b2: np.ndarray, yy: float, n: int):
    """−MLL (without (n/2) log 2π) and its gradient in (log s, log σ²), from M's eigenvalues e (P,), b² (P,), yᵀy."""
    p = e.shape[0]

    def neg_mll(log_params: np.ndarray) -> tuple[float, np.ndarray]:
        s, s2 = np.exp(log_params)
        d = s2 + s * e
        fit = max(yy - s * np.sum(b2 / d), 0.0)                             # yᵀ(I − sΨ₀ (σ²I + sM)⁻¹ Ψ₀ᵀ) y
        loss = 0.5 * fit / s2 + 0.5 * ((n - p) * np.log(s2) + np.sum(np.log(d)))
        grad_s = -0.5 * np.sum(b2 / d ** 2) + 0.5 * np.sum(e / d)
        grad_s2 = -0.5 * fit / s2 ** 2 + 0.5 * s * np.sum(b2 / d ** 2) / s2 + 0.5 * ((n - p) / s2 + np.sum(1 / d))
        return loss, np.array([grad_s * s, grad_s2 * s2])

    return neg_mll
