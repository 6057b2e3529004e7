"""`gpr`'s hyper-parameter fit: the closed-form marginal likelihood, its optimum, the in-place LAPACK factorization,
and models saved with the former (gpytorch-loop) configuration."""

import json

import gpytorch
import pytest
import torch

from bodyschema.models import _gp_data, _gp_hyper, _gp_math
from bodyschema.models.contract import load_model
from bodyschema.models.gpr import GPRModel, build_exact_gp
from tests.models.test_gpr import single_thread  # noqa: F401 — autouse fixture: one thread (see its docstring)
from tests.toy_models import ToyPlanarArm

TOY = ToyPlanarArm()


def random_problem(seed: int, n: int = 40, dim: int = 3, n_out: int = 2):
    """Inputs u (n, D) in [-1, 1], targets (O, n) and log hyper-parameters θ (O, D+2) of a moderate GP."""
    gen = torch.Generator().manual_seed(seed)
    u = torch.rand(n, dim, generator=gen, dtype=torch.float64) * 2 - 1
    y = torch.randn(n_out, n, generator=gen, dtype=torch.float64)
    theta = torch.cat([torch.rand(n_out, dim, generator=gen, dtype=torch.float64) - 0.5,     # ℓ ≈ 0.6 … 1.6
                       torch.rand(n_out, 1, generator=gen, dtype=torch.float64),            # s ≈ 1 … 2.7
                       torch.full((n_out, 1), -3.0, dtype=torch.float64)], -1)              # σ² ≈ 0.05
    return u, y, theta


def neg_mll(u, y, theta):
    return _gp_math.neg_mll_and_grad(u, y, *_gp_hyper.split_log_params(theta))


def test_closed_form_mll_equals_gpytorch_exact_mll():
    u, y, theta = random_problem(seed=0)
    loss, _ = neg_mll(u, y, theta)
    lengthscale, outputscale, noise = _gp_hyper.split_log_params(theta)
    gp = build_exact_gp(u, y, 1e-6, lengthscale[:, None, :], outputscale, noise[:, None])
    gp.train()
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(gp.likelihood, gp)
    with torch.no_grad(), gpytorch.settings.max_cholesky_size(10**6):
        reference = -mll(gp(*gp.train_inputs), y) * u.shape[0]                   # (O,): gpytorch divides by n
    torch.testing.assert_close(loss, reference, rtol=1e-10, atol=0)


def test_mll_gradient_equals_central_finite_differences():
    u, y, theta = random_problem(seed=1)
    _, grad = neg_mll(u, y, theta)                                                # (O, D+2)
    step = 1e-5
    numeric = torch.empty_like(grad)
    for j in range(theta.shape[1]):
        shift = torch.zeros_like(theta)
        shift[:, j] = step
        numeric[:, j] = (neg_mll(u, y, theta + shift)[0] - neg_mll(u, y, theta - shift)[0]) / (2 * step)
    # central differences of a loss ~1e2: truncation O(step²) and rounding 1e-16 · 1e2 / 1e-5 ≈ 1e-9
    torch.testing.assert_close(grad, numeric, rtol=1e-6, atol=1e-6)


def test_in_place_factor_and_inverse_match_torch():
    u, _, theta = random_problem(seed=2, n=60)
    lengthscale, outputscale, noise = _gp_hyper.split_log_params(theta)
    k = _gp_math.rbf_train(u, lengthscale, outputscale) + noise[:, None, None] * torch.eye(60, dtype=torch.float64)
    kernel = _gp_math.rbf_train(u, lengthscale, outputscale)
    factor = _gp_math.cholesky_factor(u, lengthscale, outputscale, noise, kernel=kernel)
    torch.testing.assert_close(kernel, _gp_math.rbf_train(u, lengthscale, outputscale), rtol=0, atol=0)  # copied
    torch.testing.assert_close(factor, torch.linalg.cholesky(k), rtol=1e-10, atol=1e-12)
    assert (factor.triu(1) == 0).all()
    torch.testing.assert_close(_gp_math.inverse_from_factor(factor), torch.linalg.inv(k), rtol=1e-8, atol=1e-8)


def test_factorization_retries_with_jitter_then_refuses_a_kernel_far_from_positive_definite():
    u = torch.linspace(-1, 1, 30, dtype=torch.float64)[:, None].repeat_interleave(2, 0)   # (60, 1): each point twice
    lengthscale, outputscale = torch.tensor([[0.5]], dtype=torch.float64), torch.tensor([1.0], dtype=torch.float64)
    # duplicated points make K singular: a slightly negative noise fails the first factorization, jitter repairs it
    factor = _gp_math.cholesky_factor(u, lengthscale, outputscale, torch.tensor([-1e-9], dtype=torch.float64))
    k = _gp_math.rbf_train(u, lengthscale, outputscale)
    assert torch.isfinite(factor).all()
    torch.testing.assert_close(factor @ factor.mT, k, rtol=0, atol=1e-6)        # jitter ≤ 1e-6 · s was added
    with pytest.raises(RuntimeError, match="not positive definite even with jitter"):
        _gp_math.cholesky_factor(u, lengthscale, outputscale, torch.tensor([-0.1], dtype=torch.float64))


def test_fitted_hyper_parameters_are_a_local_optimum_of_the_mll():
    # 320 noisy toy poses, all of them in the hyper subset (so the coarse 150-point run happens, then the fine one)
    gen = torch.Generator().manual_seed(5)
    q = torch.rand(320, 2, generator=gen, dtype=torch.float64) * 4 - 2                   # (320, 2) rad
    x = TOY.predict(q) + 1e-3 * torch.randn(320, 3, generator=gen, dtype=torch.float64)   # (320, 3) m
    steps = []
    model = GPRModel(TOY.body, "ee_xyz", (3,), hyper_points=320, max_points=320, kernel="rbf").fit(
        q, x, progress=False, on_epoch=lambda step, metrics: steps.append(step))
    u, (ys, _, _) = TOY.body.to_unit(q), _gp_data.standardize(x)
    theta = torch.cat([model.lengthscale_.log(), model.outputscale_.log()[:, None], model.noise_.log()[:, None]], -1)
    loss = neg_mll(u, ys, theta)[0]                                                 # (3,)
    start = _gp_hyper.initial_log_params(3, _gp_hyper.log_bounds(2, model.noise_floor))
    assert (loss < neg_mll(u, ys, start)[0]).all()
    bounds = torch.from_numpy(_gp_hyper.log_bounds(2, model.noise_floor))
    # no move of ±0.05 in one log hyper-parameter (within the bounds) gains more than L-BFGS-B's stopping tolerance
    tolerance = _gp_hyper.FINE_FTOL * loss.abs()
    for j in range(theta.shape[1]):
        for sign in (-1.0, 1.0):
            moved = theta.clone()
            moved[:, j] = (moved[:, j] + sign * 0.05).clamp(bounds[j, 0], bounds[j, 1])
            assert (neg_mll(u, ys, moved)[0] >= loss - tolerance).all(), (j, sign)
    assert steps == list(range(1, len(steps) + 1))


def test_a_model_saved_with_the_former_gpytorch_loop_config_loads_and_predicts_the_same(tmp_path):
    # Until issue 21 the defaults were 50 Adam steps (on softplus⁻¹ parameters), 200 L-BFGS evaluations and a 1e-7
    # noise floor; STATE_KEYS did not change. Such a save: this fit's state under the former config.
    gen = torch.Generator().manual_seed(8)
    q = torch.rand(80, 2, generator=gen, dtype=torch.float64) * 4 - 2
    model = GPRModel(TOY.body, "ee_xyz", (3,)).fit(q, TOY.predict(q), progress=False)
    model.save(tmp_path)
    meta = json.loads((tmp_path / "meta.json").read_text())
    meta["config"].update({"adam_steps": 50, "lbfgs_steps": 200, "lr": 0.05, "noise_floor": 1e-7})
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    loaded = load_model(tmp_path)
    assert (loaded.adam_steps, loaded.noise_floor) == (50, 1e-7)
    z = torch.rand(9, 2, generator=gen, dtype=torch.float64) * 4 - 2
    torch.testing.assert_close(loaded.predict(z), model.predict(z), rtol=0, atol=0)
    torch.testing.assert_close(loaded.jacobian(z), model.jacobian(z), rtol=0, atol=0)
    torch.testing.assert_close(loaded.precision(z), model.precision(z), rtol=1e-9, atol=0)   # factor recomputed


def test_a_fit_stranded_on_the_tiny_lengthscale_plateau_is_searched_again_from_the_start():
    # The toy arm's x, noise-free, 200 poses; a search started at ℓ = 1e-3 on every joint (K ≈ s·I: where the coarse
    # run left SO-101's y output) stays there: its −MLL is that of independent noise. The restart finds structure.
    gen = torch.Generator().manual_seed(3)
    q = torch.rand(200, 2, generator=gen, dtype=torch.float64) * 4 - 2                  # (200, 2) rad
    u, (ys, _, _) = TOY.body.to_unit(q), _gp_data.standardize(TOY.predict(q))
    bounds = _gp_hyper.log_bounds(2, 3e-8)
    stranded = torch.tensor([bounds[0, 0], bounds[1, 0], 0.0, -3.0], dtype=torch.float64)   # ℓ at the lower bound

    def evaluate(row):                                                                 # θ (D+2,) of output x
        return neg_mll(u, ys[:1], row[None])

    theta, loss = _gp_hyper.lbfgs(evaluate, stranded, bounds, 200, _gp_hyper.FINE_FTOL)
    assert loss / 200 > _gp_hyper.iid_neg_mll(ys[0]) - _gp_hyper.PLATEAU_NATS       # stuck: no better than noise
    again, again_loss = _gp_hyper.restart_if_better(evaluate, theta, loss, bounds, 200)
    assert again_loss / 200 < _gp_hyper.iid_neg_mll(ys[0]) - 1.0                     # found the arm's structure
    assert float(evaluate(again)[0][0]) == pytest.approx(again_loss)                 # the loss is the θ's own
