"""Sensory terms of the Laplace free energy for any set of SensoryModels over the same latent z.

    F_x = Σ_m ½ ε_mᵀ Π_m ε_m − ½ ln|Π_m|,   ε_m = x_m − g_m(μ)        (Friston 2010, Laplace free energy;
                                                                      Pixel-AIF, Sancaktar et al. 2020, eq. 4)
    ∂F_x/∂μ = −Σ_m J_mᵀ Π_m ε_m + (∂Π_m/∂μ)ᵀ(½ ε_m² − ½ Π_m⁻¹)       (J_m = ∂g_m/∂μ; the second term only
                                                                      where Π_m = Π_m(μ): GPR, MDN)
    H_x     =  Σ_m J_mᵀ Π_m J_m                                        (Gauss–Newton curvature)
Constants (2π) are dropped. Π_m is diagonal; entries with Π = 0 (a broken sensor) leave F, its gradient and
its log-determinant. Low-dimensional outputs use `model.jacobian` once for both gradient and curvature.
Large outputs (images) take the gradient through `model.vjp` when no curvature is needed; when the integrator
needs the curvature, the Jacobian is built over chunks of the batch (bounded memory) and serves the gradient
too, so no VJP is spent on top of it.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from bodyschema.errors import must_be
from bodyschema.models.contract import SensoryModel
from bodyschema.models.scaling import BodySpec

JACOBIAN_MAX_OUTPUTS = 64        # above this many outputs a model's gradient goes through vjp
CHUNK_ELEMENTS = 2_000_000       # cap on B_chunk·O·Dz when a large Jacobian is built for the curvature


@dataclass
class SensoryTerms:
    free_energy: torch.Tensor              # (B,)
    grad: torch.Tensor                     # (B, Dz) ∂F_x/∂μ
    hessian: torch.Tensor | None           # (B, Dz, Dz) Gauss–Newton, when asked for
    weighted: dict[str, torch.Tensor]      # modality → (B,) ½ εᵀΠε


def check_models(models: Sequence[SensoryModel]) -> BodySpec:
    """All models must describe the same robot and joints, with distinct modalities; returns their body."""
    if len(models) == 0:
        raise ValueError(must_be("models", "a non-empty sequence of SensoryModels", list(models)))
    for i, m in enumerate(models):
        if not isinstance(m, SensoryModel):
            raise TypeError(must_be(f"models[{i}]", "a SensoryModel (see bodyschema.models.contract)",
                                    type(m).__name__))
    body = models[0].body
    for i, m in enumerate(models[1:], start=1):
        body.check_compatible(m.body, what=f"models[{i}] ({m.modality})")
    modalities = [m.modality for m in models]
    if len(set(modalities)) != len(modalities):
        raise ValueError(must_be("model modalities", "distinct (one model per modality)", modalities,
                                 "Fuse models of different modalities; compare same-modality models in separate runs."))
    return body


def check_observations(models: Sequence[SensoryModel], observations: Mapping[str, torch.Tensor], batch: int,
                       optional: set[str] = frozenset()) -> None:
    """Every modality needs an observation of shape (B, *output_shape); modalities in `optional` may be absent."""
    if not isinstance(observations, Mapping):
        raise TypeError(must_be("observations", "a dict modality → tensor", type(observations).__name__))
    expected = {m.modality: m for m in models}
    unknown = sorted(set(observations) - set(expected))
    if unknown:
        raise ValueError(must_be("observations keys", f"modalities of the models {sorted(expected)}", unknown,
                                 "Drop the extra observations or add a model for them."))
    for name, m in expected.items():
        if name not in observations:
            if name in optional:
                continue
            raise ValueError(must_be(f"observations[{name!r}]", "present", "missing",
                                     f"Pass a tensor of shape (B, {', '.join(map(str, m.output_shape))})."))
        x = observations[name]
        want = (batch, *m.output_shape)
        if not isinstance(x, torch.Tensor) or tuple(x.shape) != want:
            got = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
            raise ValueError(must_be(f"observations[{name!r}]", f"a tensor of shape {want}", got,
                                     "One observation per trial, in the model's output units."))
        if not torch.is_floating_point(x) or not torch.isfinite(x).all():
            raise ValueError(must_be(f"observations[{name!r}]", "a finite floating-point tensor",
                                     f"dtype {x.dtype}", "Convert images to float in the model's intensity range."))


def model_input(model: SensoryModel, mu: torch.Tensor) -> torch.Tensor:
    """μ in the dtype the model computes in (optional `compute_dtype`, e.g. float32 for networks): the belief and
    the update stay float64, a network is not run through a ~10× slower float64 copy of its float32 weights."""
    return mu.to(getattr(model, "compute_dtype", mu.dtype))


def sensory_terms(models: Sequence[SensoryModel], observations: Mapping[str, torch.Tensor],
                  precisions: Mapping[str, torch.Tensor | None], mu: torch.Tensor, need_hessian: bool,
                  jacobian_max_outputs: int = JACOBIAN_MAX_OUTPUTS, need_grad: bool = True) -> SensoryTerms:
    """F_x, its gradient and (optionally) its Gauss–Newton curvature at beliefs mu (B, Dz).

    `precisions[modality]` is a (B, *out) tensor, or None to ask the model (`model.precision(mu)`).
    Modalities absent from `observations` are skipped (callers drop modalities of zero precision).
    need_grad=False evaluates F only (no Jacobian, no VJP); the gradient is then left at zero.
    """
    b, dz = mu.shape
    free = torch.zeros(b, dtype=mu.dtype)
    grad = torch.zeros(b, dz, dtype=mu.dtype)
    hess = torch.zeros(b, dz, dz, dtype=mu.dtype) if need_hessian else None
    weighted = {}
    for m in models:
        if m.modality not in observations:
            continue
        x = observations[m.modality].to(mu.dtype)                          # (B, *out)
        z = model_input(m, mu)
        pi = precisions.get(m.modality)
        varies = pi is None and getattr(m, "precision_varies", False)     # Π(μ): its derivative enters ∂F/∂μ
        pi = m.precision(z).to(mu.dtype) if pi is None else pi.to(mu.dtype)  # (B, *out)
        n_out = x[0].numel()
        small = n_out <= jacobian_max_outputs
        pred, jac, vjp = _evaluated(m, z, small, need_grad, need_hessian, b * n_out * dz)
        jac = jac.to(mu.dtype) if jac is not None else None                # (B, O, Dz)
        eps = (x - pred.to(mu.dtype)).reshape(b, n_out)                    # (B, O) ε = x − g(μ)
        pi = pi.reshape(b, n_out)
        pe = pi * eps                                                      # (B, O) Π ε
        jt_pe = None                                                       # (B, Dz) Jᵀ Π ε
        if need_hessian:
            curvature, jt_pe = _gauss_newton(m, mu, pi, pe, jac)
            hess += curvature
        if need_grad:
            if jt_pe is None:
                jt_pe = torch.einsum("bod,bo->bd", jac, pe) if small else \
                    vjp(pe.reshape(x.shape).to(z.dtype)).to(mu.dtype)
            grad -= jt_pe                                                  # −Jᵀ Π ε
            if varies:                                                     # + (∂Π/∂μ)ᵀ (½ε² − ½Π⁻¹)
                w = 0.5 * eps.pow(2) - 0.5 * torch.where(pi > 0, 1.0 / pi.clamp_min(1e-300), torch.zeros_like(pi))
                grad += m.precision_vjp(z, w.reshape(x.shape).to(z.dtype)).to(mu.dtype)
        term = 0.5 * (pe * eps).sum(-1)
        logdet = torch.where(pi > 0, pi.clamp_min(1e-300).log(), torch.zeros_like(pi)).sum(-1)
        free += term - 0.5 * logdet
        weighted[m.modality] = term
    return SensoryTerms(free, grad, hess, weighted)


def _evaluated(m: SensoryModel, z: torch.Tensor, small: bool, need_grad: bool, need_hessian: bool, elements: int):
    """g(z), its Jacobian when it is wanted whole (None: not needed, or built in chunks by _gauss_newton) and a VJP.
    A large output (an image) takes g with what the step needs from one forward where the model offers it:
    g and Jᵀv for a gradient step, g and J for a Gauss–Newton one (when J fits in CHUNK_ELEMENTS)."""
    vjp = functools.partial(m.vjp, z)
    if small:
        return m.predict(z), (m.jacobian(z) if need_grad else None), vjp
    if need_hessian and elements <= CHUNK_ELEMENTS and hasattr(m, "predict_and_jacobian"):
        return (*m.predict_and_jacobian(z), vjp)
    if need_grad and not need_hessian and hasattr(m, "predict_and_vjp"):
        pred, fused_vjp = m.predict_and_vjp(z)
        return pred, None, fused_vjp
    return m.predict(z), None, vjp


def _gauss_newton(model: SensoryModel, mu: torch.Tensor, pi: torch.Tensor, pe: torch.Tensor,
                  jac: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    """Jᵀ Π J and Jᵀ Π ε per trial from one Jacobian. pi, pe (B, O); jac (B, O, Dz), or None to build it
    chunk by chunk. → (B, Dz, Dz), (B, Dz)"""
    if jac is not None:
        return torch.einsum("bod,bo,boe->bde", jac, pi, jac), torch.einsum("bod,bo->bd", jac, pe)
    b, n_out = pi.shape
    step = max(1, CHUNK_ELEMENTS // (n_out * mu.shape[1]))
    curvature, gradient = [], []
    for s in range(0, b, step):
        j = model.jacobian(model_input(model, mu[s:s + step])).to(mu.dtype)  # (b_chunk, O, Dz)
        curvature.append(torch.einsum("bod,bo,boe->bde", j, pi[s:s + step], j))
        gradient.append(torch.einsum("bod,bo->bd", j, pe[s:s + step]))
    return torch.cat(curvature), torch.cat(gradient)
