"""Generalized coordinates of motion: the shift operator D and the local-linearization integrator.

A belief in generalized coordinates of order n holds K = n + 1 blocks per trial, μ̃ = (μ, μ', μ'', …):
a tensor `(B, K, Dz)`. D shifts every block up one order, (Dμ̃)^(i) = μ^(i+1), and the last block to 0
(the motion is truncated at order n; Friston, Stephan, Li & Daunizeau 2010, "Generalised filtering", eq. 2).

The integrator of a flow u̇ = h(u) with Jacobian 𝓙 = ∂h/∂u is Ozaki's local linearization (Ozaki 1992;
Friston 2008 "DEM" eq. 13):
    Δu = (exp(Δt 𝓙) − I) 𝓙⁻¹ u̇ = Δt φ₁(Δt 𝓙) u̇,     φ₁(A) = Σ_k A^k / (k+1)!
It is exact for linear flows and unconditionally stable for stable ones; on a pure gradient flow
u̇ = −k ∇F with 𝓙 = −k H it tends to the Newton step −H⁻¹∇F as Δt → ∞ and to Euler as Δt → 0. φ₁ is read off
the exponential of an augmented matrix, so a singular 𝓙 (unobservable joint, broken sensor) needs no inverse:
    exp([[A, I], [0, 0]]) = [[exp(A), φ₁(A)], [0, I]]   (Higham 2008, "Functions of Matrices", §10.7.4).
"""

from __future__ import annotations

import torch


def shift(u: torch.Tensor) -> torch.Tensor:
    """Dμ̃: every order moves up one, the highest becomes 0. # (B, K, Dz) → (B, K, Dz)"""
    return torch.cat([u[:, 1:], torch.zeros_like(u[:, :1])], dim=1)


def shift_matrix(order: int, latent_dim: int, dtype=torch.float64) -> torch.Tensor:
    """D ⊗ I_Dz as a dense matrix on the flattened belief vec(μ̃) (order-major). # (K·Dz, K·Dz)"""
    k = order + 1
    d = torch.diag(torch.ones(k - 1, dtype=dtype), diagonal=1)            # (K, K), ones above the diagonal
    return torch.kron(d, torch.eye(latent_dim, dtype=dtype))


def phi1(a: torch.Tensor) -> torch.Tensor:
    """φ₁(A) = (exp(A) − I) A⁻¹ for a batch of square matrices, via the augmented exponential. # (B, N, N)"""
    b, n, _ = a.shape
    aug = torch.zeros(b, 2 * n, 2 * n, dtype=a.dtype, device=a.device)   # (B, 2N, 2N)
    aug[:, :n, :n] = a
    aug[:, :n, n:] = torch.eye(n, dtype=a.dtype, device=a.device)
    return torch.linalg.matrix_exp(aug)[:, :n, n:]


def _per_row(dt: float | torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """Δt as a (B, 1) column: one step size for all rows, or one per row (adaptive step control)."""
    return torch.as_tensor(dt, dtype=flow.dtype).expand(flow.shape[0]).reshape(-1, 1)


def local_linear_step(flow: torch.Tensor, flow_jacobian: torch.Tensor, dt: float | torch.Tensor) -> torch.Tensor:
    """Δu = Δt φ₁(Δt 𝓙) u̇ (Ozaki 1992). flow (B, N), flow_jacobian (B, N, N), dt scalar or (B,) → (B, N).

    A symmetric 𝓙 (order 0: 𝓙 = −k H) goes through its eigendecomposition, φ₁ applied to the eigenvalues
    (an order of magnitude faster than a batched matrix exponential); otherwise the augmented exponential.
    """
    dt = _per_row(dt, flow)                                               # (B, 1)
    if torch.equal(flow_jacobian, flow_jacobian.transpose(1, 2)):
        lam, vec = torch.linalg.eigh(dt[:, :, None] * flow_jacobian)      # (B, N), (B, N, N)
        small = lam.abs() < 1e-8
        ratio = torch.where(small, 1.0 + lam / 2, torch.expm1(lam) / torch.where(small, 1.0, lam))
        coeff = torch.einsum("bji,bj->bi", vec, flow) * ratio             # φ₁(λ) · Vᵀ u̇
        return dt * torch.einsum("bij,bj->bi", vec, coeff)
    return dt * torch.einsum("bij,bj->bi", phi1(dt[:, :, None] * flow_jacobian), flow)


def implicit_step(flow: torch.Tensor, flow_jacobian: torch.Tensor, dt: float | torch.Tensor) -> torch.Tensor:
    """Linearly implicit Euler, Δu = (I − Δt 𝓙)⁻¹ Δt u̇ (Rosenbrock 1963): L-stable, Newton as Δt → ∞,
    one batched solve instead of an exponential. flow (B, N), flow_jacobian (B, N, N) → (B, N)."""
    eye = torch.eye(flow.shape[1], dtype=flow.dtype, device=flow.device)
    dt = _per_row(dt, flow)                                               # (B, 1)
    return torch.linalg.solve(eye - dt[:, :, None] * flow_jacobian, dt * flow)
