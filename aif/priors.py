"""Prior dynamics f of the belief in generalized coordinates, and their free-energy term.

The prior prediction error is ε_z = Dμ̃ − f̃(μ̃) (Friston et al. 2010, "Generalised filtering", eq. 3), with the
generalized motion of f under local linearization (Friston 2008, "DEM", eq. 6):
    f̃^(0) = f(μ),   f̃^(i) = A μ^(i) for i ≥ 1,   A = ∂f/∂μ,   and μ^(K) ≡ 0 (truncation at order n = K − 1).
Kinds:
  "none"      no prior term (F holds the sensory terms only; higher orders stay at their start, 0).
  "damping"   f = 0: the body is believed still, every velocity decays with precision Π_z.
  "attractor" f(μ) = β J_gᵀ (x_d − g(μ)): the belief is pulled toward a goal x_d in a model's output space
              (the issue's f(z, x_d) = (∂g/∂z)ᵀ Π (x_d − g(z)) with Π = β I); A ≈ −β J_gᵀ J_g (Gauss–Newton,
              second derivatives of g dropped).
Its free-energy term ½ Σ_i ε_z^(i)ᵀ Π_z ε_z^(i) − ½ K·Dz ln Π_z has gradient Lᵀ Π_z ε_z and Gauss–Newton
Hessian Π_z Lᵀ L with L = ∂ε_z/∂vec(μ̃) = D ⊗ I − I_K ⊗ A.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from bodyschema.aif.generalized import shift, shift_matrix

PRIORS = ("none", "damping", "attractor")


@dataclass
class PriorTerms:
    free_energy: torch.Tensor    # (B,)
    grad: torch.Tensor           # (B, K, Dz) ∂F_z/∂μ̃
    hessian: torch.Tensor        # (B, K·Dz, K·Dz) Gauss–Newton
    error: torch.Tensor          # (B, K, Dz) ε_z


def attractor_flow(pred: torch.Tensor, jac: torch.Tensor, goal: torch.Tensor, gain: float):
    """f(μ) = β Jᵀ (x_d − g(μ)) and A = −β JᵀJ. pred/goal (B, *out), jac (B, O, Dz) → (B, Dz), (B, Dz, Dz)."""
    residual = (goal - pred).reshape(pred.shape[0], -1)                    # (B, O)
    f0 = gain * torch.einsum("bod,bo->bd", jac, residual)                  # (B, Dz)
    a = -gain * torch.einsum("bod,boe->bde", jac, jac)                     # (B, Dz, Dz)
    return f0, a


def prior_terms(u: torch.Tensor, kind: str, precision: float, f0: torch.Tensor | None = None,
                a: torch.Tensor | None = None) -> PriorTerms | None:
    """The prior term of F for beliefs u (B, K, Dz); None for kind "none". f0 (B, Dz), a (B, Dz, Dz): attractor."""
    if kind == "none":
        return None
    b, k, dz = u.shape
    if f0 is None:                                                         # damping: f = 0, A = 0
        f0 = torch.zeros(b, dz, dtype=u.dtype)
        a = torch.zeros(b, dz, dz, dtype=u.dtype)
    higher = torch.einsum("bde,bke->bkd", a, u[:, 1:])                     # (B, K−1, Dz): A μ^(i), i ≥ 1
    f_tilde = torch.cat([f0[:, None], higher], dim=1)                      # (B, K, Dz)
    eps = shift(u) - f_tilde                                               # (B, K, Dz) ε_z = Dμ̃ − f̃
    d = shift_matrix(k - 1, dz, u.dtype)                                   # (K·Dz, K·Dz)
    lin = d - torch.kron(torch.eye(k, dtype=u.dtype), torch.ones(dz, dz, dtype=u.dtype))[None] \
        * a.repeat(1, k, k)                                                # (B, K·Dz, K·Dz): D⊗I − I_K⊗A
    flat = eps.reshape(b, k * dz)                                          # (B, K·Dz)
    grad = precision * torch.einsum("bij,bi->bj", lin, flat).reshape(b, k, dz)
    hess = precision * torch.einsum("bij,bik->bjk", lin, lin)
    free = 0.5 * precision * flat.pow(2).sum(-1) - 0.5 * k * dz * math.log(precision)
    return PriorTerms(free, grad, hess, eps)
