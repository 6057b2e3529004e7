"""The shift operator and the local-linearization integrator against closed forms."""

from __future__ import annotations

import torch

from bodyschema.aif.generalized import local_linear_step, phi1, shift, shift_matrix
from bodyschema.aif.priors import prior_terms


def test_shift_moves_orders_up_and_truncates():
    u = torch.arange(12, dtype=torch.float64).reshape(2, 3, 2)            # (B, K, Dz)
    d = shift(u)
    torch.testing.assert_close(d[:, :2], u[:, 1:])
    assert (d[:, 2] == 0).all()
    flat = torch.einsum("ij,bj->bi", shift_matrix(2, 2), u.reshape(2, 6)).reshape(2, 3, 2)
    torch.testing.assert_close(flat, d)


def test_phi1_matches_its_definition_and_handles_singular_matrices():
    g = torch.Generator().manual_seed(0)
    a = torch.randn(4, 3, 3, generator=g, dtype=torch.float64)
    expected = (torch.linalg.matrix_exp(a) - torch.eye(3, dtype=torch.float64)) @ torch.linalg.inv(a)
    torch.testing.assert_close(phi1(a), expected, rtol=1e-9, atol=1e-9)
    torch.testing.assert_close(phi1(torch.zeros(1, 3, 3, dtype=torch.float64))[0], torch.eye(3, dtype=torch.float64))


def test_local_linear_step_is_exact_for_a_linear_flow_and_newton_in_the_limit():
    h = torch.tensor([[[2.0, 0.5], [0.5, 1.0]]], dtype=torch.float64)     # SPD curvature of F = ½ uᵀHu
    u = torch.tensor([[1.0, -2.0]], dtype=torch.float64)
    flow = -torch.einsum("bij,bj->bi", h, u)
    du = local_linear_step(flow, -h, dt=0.7)
    exact = torch.einsum("bij,bj->bi", torch.linalg.matrix_exp(-0.7 * h), u)
    torch.testing.assert_close(u + du, exact, rtol=1e-10, atol=1e-12)
    newton = local_linear_step(flow, -h, dt=1e4)
    torch.testing.assert_close(u + newton, torch.zeros_like(u), rtol=0, atol=1e-9)


def test_prior_gradient_and_curvature_match_autograd_for_linear_dynamics():
    g = torch.Generator().manual_seed(1)
    u = torch.randn(3, 3, 2, generator=g, dtype=torch.float64, requires_grad=True)
    c = torch.randn(3, 2, generator=g, dtype=torch.float64)
    a = torch.randn(3, 2, 2, generator=g, dtype=torch.float64)
    f0 = torch.einsum("bde,be->bd", a, u[:, 0]) + c                        # a linear f: its A is exact
    terms = prior_terms(u, "attractor", 2.0, f0, a)
    (auto,) = torch.autograd.grad(terms.free_energy.sum(), u)
    torch.testing.assert_close(terms.grad, auto)
    one = lambda v: prior_terms(v.reshape(1, 3, 2), "attractor", 2.0,    # noqa: E731 — F of one sample
                                a[:1] @ v.reshape(3, 2)[0] + c[:1], a[:1]).free_energy.sum()
    hess = torch.autograd.functional.hessian(one, u[0].detach().reshape(-1))
    torch.testing.assert_close(terms.hessian[0], hess)                     # linear ε: Gauss–Newton is exact
    assert prior_terms(u, "none", 1.0) is None
