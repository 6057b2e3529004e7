"""Prior dynamics f of the belief in generalized coordinates, and their free-energy term.

The prior prediction error is ε_z = Dμ̃ − f̃(μ̃) (Friston et al. 2010, "Generalised filtering", eq. 3), with the
generalized motion of f under local linearization (Friston 2008, "DEM", eq. 6):
    f̃^(0) = f(μ),   f̃^(i) = A μ^(i) for i ≥ 1,   A = ∂f/∂μ,   and μ^(K) ≡ 0 (truncation at order n = K − 1).
Kinds:
  "none"      no prior term (F holds the sensory terms only; higher orders stay at their start, 0).
  "damping"   f = 0: the body is believed still, every velocity decays with precision Π_z.
  "attractor" the belief is pulled toward a goal x_d in a model's output space, with Π = β Π_g (β the gain, Π_g the
              goal's precision: the goal model's own, or 1):
                "gradient"      f(μ) = J_gᵀ Π (x_d − g(μ))                      (the issue's f(z, x_d));
                                A ≈ −J_gᵀ Π J_g (Gauss–Newton: second derivatives of g dropped)
                "gauss_newton"  f(μ) = β (J_gᵀ W J_g + λ I)⁻¹ J_gᵀ W (x_d − g(μ)), Π = β W with W's mean 1
                                (damped least squares, Wampler 1986; λ = δ·tr(JᵀWJ)/Dz); A ≈ −β (JᵀWJ + λI)⁻¹ JᵀWJ.
                                J f ≈ β (x_d − g): the output moves straight along its error at rate β (1/s),
                                whatever the arm's redundancy or the skew of Jᵀ (a 7-DOF arm crawls along Jᵀe's
                                weak directions).
Its free-energy term at order n ≥ 1 is ½ Σ_i ε_z^(i)ᵀ Π_z ε_z^(i) − ½ K·Dz ln Π_z with gradient Lᵀ Π_z ε_z and
Gauss–Newton Hessian Π_z Lᵀ L, L = ∂ε_z/∂vec(μ̃) = D ⊗ I − I_K ⊗ A.
At order 0 (K = 1) Dμ̃ = 0, so ε_z = −f(μ) would make the attractor the penalty ½ Π_z |f|², with β entering squared
and a pull ∝ JᵀΠJ·JᵀΠ(x_d − g) instead of f. Instead the order-0 attractor is its potential: for the gradient
geometry f = −∂V/∂μ with V = ½ (x_d − g)ᵀ Π (x_d − g), so F_z = Π_z V gives −∂F_z/∂μ = Π_z f exactly as
documented, with Gauss–Newton curvature −Π_z A = Π_z JᵀΠJ; the perception's own damped Gauss–Newton step
(local_linear, 𝓙 = −k H) then preconditions it with the same geometry as every sensory term. The gauss_newton
f is not a gradient field, so order 0 takes the gradient geometry.
Large outputs (images): f = vjp(μ, Π (x_d − g)), never the (B, O, Dz) Jacobian; A is then unavailable (None), so
image goals are order-0 only (perception fuses an observed image with its goal, perception.Perception._terms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from bodyschema.aif.free_energy import JACOBIAN_MAX_OUTPUTS, model_input
from bodyschema.aif.generalized import shift, shift_matrix
from bodyschema.errors import must_be

PRIORS = ("none", "damping", "attractor")
GEOMETRIES = ("gradient", "gauss_newton")
GN_DAMPING = 1e-2     # δ: λ = δ·tr(JᵀΠJ)/Dz, so the damped inverse stays bounded at singular poses (unitless)


@dataclass
class PriorTerms:
    free_energy: torch.Tensor    # (B,)
    grad: torch.Tensor           # (B, K, Dz) ∂F_z/∂μ̃
    hessian: torch.Tensor        # (B, K·Dz, K·Dz) Gauss–Newton
    error: torch.Tensor          # (B, K, Dz) ε_z
    energy: torch.Tensor | None = None   # (B,) the term without its log-determinant; None: ½ Π_z |ε_z|²


@dataclass
class Attractor:
    flow: torch.Tensor                 # (B, Dz) f(μ)
    jacobian: torch.Tensor | None      # (B, Dz, Dz) A ≈ ∂f/∂μ; None for an image goal (no Jacobian is built)
    potential: torch.Tensor            # (B,) V = ½ (x_d − g)ᵀ Π (x_d − g)


def attractor_flow(pred: torch.Tensor, jac: torch.Tensor, goal: torch.Tensor, gain: float | torch.Tensor,
                   geometry: str = "gradient", damping: float = GN_DAMPING):
    """f(μ) and A ≈ ∂f/∂μ of the attractor with Π = gain (a float, or (B, *out) per output).
    pred/goal (B, *out), jac (B, O, Dz) → (B, Dz), (B, Dz, Dz)."""
    b = pred.shape[0]
    residual = (goal - pred).reshape(b, -1)                                # (B, O)
    pi = torch.as_tensor(gain, dtype=pred.dtype).expand(pred.shape).reshape(b, -1)   # (B, O)
    pull = torch.einsum("bod,bo->bd", jac, pi * residual)                 # (B, Dz) Jᵀ Π (x_d − g)
    curv = torch.einsum("bod,bo,boe->bde", jac, pi, jac)                  # (B, Dz, Dz) Jᵀ Π J
    if geometry == "gradient":
        return pull, -curv
    if geometry != "gauss_newton":
        raise ValueError(must_be("geometry", f"one of {GEOMETRIES}", geometry))
    rate = pi.mean(-1)[:, None, None]                                     # (B, 1, 1) β: Π = β W, mean W = 1
    dz = jac.shape[-1]
    eye = torch.eye(dz, dtype=pred.dtype)
    lam = damping * torch.diagonal(curv, dim1=1, dim2=2).mean(-1).clamp_min(1e-300)   # (B,)
    damped = curv + lam[:, None, None] * eye                               # (B, Dz, Dz) β (JᵀWJ + λ I)
    f0 = rate[..., 0] * torch.linalg.solve(damped, pull)                   # (B, Dz) β (JᵀWJ + λ)⁻¹ JᵀW (x_d − g)
    return f0, -rate * torch.linalg.solve(damped, curv)


def attractor(model, mu: torch.Tensor, goal: torch.Tensor, gain: float, precision: torch.Tensor | None = None,
              geometry: str = "gradient") -> Attractor:
    """The attractor toward goal x_d (B, *out) through `model` at beliefs mu (B, Dz): Π = gain · precision
    ((B, *out); None: the model's own precision). Images: f by one VJP, A None."""
    b = mu.shape[0]
    z = model_input(model, mu)
    pred = model.predict(z).to(mu.dtype)                                   # (B, *out)
    pi = gain * (model.precision(z).to(mu.dtype) if precision is None else precision.to(mu.dtype))
    residual = goal.to(mu.dtype) - pred                                    # (B, *out)
    potential = 0.5 * (pi * residual.pow(2)).reshape(b, -1).sum(-1)        # (B,)
    if pred[0].numel() > JACOBIAN_MAX_OUTPUTS:
        if geometry != "gradient":
            raise ValueError(must_be("geometry of an image goal", "'gradient'", geometry,
                                     "An image goal's Gauss–Newton flow would need its full Jacobian."))
        flow = model.vjp(z, (pi * residual).to(z.dtype)).to(mu.dtype)     # (B, Dz) Jᵀ Π (x_d − g)
        return Attractor(flow, None, potential)
    f0, a = attractor_flow(pred, model.jacobian(z).to(mu.dtype), goal.to(mu.dtype), pi, geometry)
    return Attractor(f0, a, potential)


def prior_terms(u: torch.Tensor, kind: str, precision: float, f0: torch.Tensor | None = None,
                a: torch.Tensor | None = None, potential: torch.Tensor | None = None) -> PriorTerms | None:
    """The prior term of F for beliefs u (B, K, Dz); None for kind "none". f0 (B, Dz), a (B, Dz, Dz) or None (an
    image goal): attractor; potential (B,): its V, needed at order 0 (K = 1, see the module docstring)."""
    if kind == "none":
        return None
    b, k, dz = u.shape
    if f0 is None:                                                         # damping: f = 0, A = 0
        f0 = torch.zeros(b, dz, dtype=u.dtype)
        a = torch.zeros(b, dz, dz, dtype=u.dtype)
    if k == 1 and kind == "attractor":
        return _potential_terms(u, precision, f0, a, potential)
    if a is None:
        raise ValueError(must_be("the attractor's A", "available above order 0", None,
                                 "Image goals are order-0 only (their flow Jacobian needs the full Jacobian)."))
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


def _potential_terms(u, precision, f0, a, potential) -> PriorTerms:
    """Order 0: F_z = Π_z V, ∂F_z/∂μ = −Π_z f, H = −Π_z A (zero without A). ε_z is reported as −f."""
    if potential is None:
        raise ValueError(must_be("potential", "V (B,) of the attractor at order 0", None,
                                 "Pass Attractor.potential: at order 0 the attractor enters F as Π_z V."))
    b, _, dz = u.shape
    hess = torch.zeros(b, dz, dz, dtype=u.dtype) if a is None else -precision * 0.5 * (a + a.transpose(1, 2))
    return PriorTerms(precision * potential, -precision * f0[:, None], hess, -f0[:, None], precision * potential)
