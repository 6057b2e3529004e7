"""`gpr` (gpytorch exact GP): the shared contract on the toy arm, plus accuracy, exact solves and fit errors."""

import os

import numpy as np
import pytest
import torch
from threadpoolctl import threadpool_limits

from bodyschema.models.gpr import GPRModel
from tests.models.contract import SensoryModelContract
from tests.toy_models import ToyPlanarArm

TOY = ToyPlanarArm()
REACH_M = 0.55   # toy arm reach: the noise-free output scale


THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


@pytest.fixture(autouse=True, scope="module")
def single_thread():
    """One BLAS/OpenMP thread, here and in the contract's fresh-process reload (which inherits the env vars).

    Small GP matrices: with other processes busy on the 2-core dev VM, 2 OpenMP threads made a 3×200² Cholesky
    take 31 ms instead of 0.35 ms (threads wait for descheduled peers). And a reload is bit-identical only under
    the same thread counts, since BLAS rounding depends on how a product is split over threads.
    """
    saved = {name: os.environ.get(name) for name in THREAD_VARS}
    threads = torch.get_num_threads()
    os.environ.update({name: "1" for name in THREAD_VARS})
    torch.set_num_threads(1)
    with threadpool_limits(limits=1):
        yield
    torch.set_num_threads(threads)
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name)
        else:
            os.environ[name] = value


def toy_data(n: int, seed: int, low: float = -2.0, high: float = 2.0):
    """n random toy-arm poses (rad) inside the model range and their noise-free ee_xyz (m)."""
    gen = torch.Generator().manual_seed(seed)
    q = torch.rand(n, 2, generator=gen, dtype=torch.float64) * (high - low) + low   # (n, 2)
    return q, TOY.predict(q)                                                        # (n, 3)


def fit_gpr(n: int, seed: int = 0, **hyper) -> GPRModel:
    q, x = toy_data(n, seed=100 + seed)
    return GPRModel(TOY.body, "ee_xyz", (3,), **hyper).fit(q, x, seed=seed, progress=False)


class TestGPR(SensoryModelContract):
    """The RBF kernel (the kinematic one: tests/models/test_gpr_kinematic.py)."""

    def make_model(self, seed):
        return fit_gpr(200, seed, kernel="rbf")

    def make_inputs(self, n, dtype=torch.float64):
        return toy_data(n, seed=n)[0].to(dtype)

    def make_unfitted_model(self):
        return GPRModel(TOY.body, "ee_xyz", (3,))

    # ---- gpr-specific checks on the same cached model -------------------------------------------------
    def test_held_out_error_and_jacobian_match_the_true_arm(self, model):
        q, x = toy_data(500, seed=7)
        err = (model.predict(q) - x).norm(dim=-1)                                     # (500,) m
        assert err.mean() < 2e-4 * REACH_M, f"mean error {err.mean():.2e} m"          # measured 2.5e-5 m
        jac_rmse = (model.jacobian(q) - TOY.jacobian(q)).pow(2).mean().sqrt()
        assert jac_rmse < 1e-3, f"Jacobian RMSE {jac_rmse:.2e} m/rad"                # measured 1.7e-4 m/rad
        std = model.precision(q)[:, :2].rsqrt()                                       # (500, 2) m
        assert (std.mean(0) < 1e-3 * REACH_M).all(), "predicted std should be far below the reach"

    def test_predict_with_jacobian_equals_the_separate_calls(self, model):
        z = toy_data(7, seed=13)[0]
        mean, jac = model.predict_with_jacobian(z)
        torch.testing.assert_close(mean, model.predict(z), rtol=0, atol=1e-10)     # m; Σ order differs
        torch.testing.assert_close(jac, model.jacobian(z), rtol=0, atol=0)
        assert all(t.dtype == torch.float32 for t in model.predict_with_jacobian(z.float()))

    def test_gpytorch_view_predicts_the_same_mean(self, model):
        import gpytorch

        z = toy_data(6, seed=14)[0]
        gp = model.to_gpytorch()
        u = TOY.body.to_unit(z)                                                       # (6, 2)
        with torch.no_grad(), gpytorch.settings.skip_posterior_variances(), gpytorch.settings.max_cholesky_size(10**6):
            mean = gp(u.expand(3, *u.shape)).mean.T * model.y_std_ + model.y_mean_     # (6, 3)
        np.testing.assert_allclose(mean.numpy(), model.predict(z).numpy(), rtol=0, atol=1e-9)


def test_precision_drops_away_from_the_training_data():
    q, x = toy_data(150, seed=3, low=-1.0, high=1.0)
    model = GPRModel(TOY.body, "ee_xyz", (3,), kernel="rbf").fit(q, x, progress=False)
    inside, outside = toy_data(50, seed=4, low=-0.8, high=0.8)[0], toy_data(50, seed=5, low=2.2, high=2.5)[0]
    assert model.precision(outside)[:, :2].max() < model.precision(inside)[:, :2].min()


def test_more_than_800_points_still_uses_exact_solves():
    # gpytorch would switch to CG above 800 points (~1000× worse on arm kinematics); with the same
    # hyper-parameters, conditioning on 1000 points must be at least as accurate as on 500 of them.
    q_test, x_test = toy_data(500, seed=9)
    q, x = toy_data(1000, seed=10)
    model = GPRModel(TOY.body, "ee_xyz", (3,), hyper_points=200).fit(q, x, progress=False)
    error_1000 = (model.predict(q_test) - x_test).norm(dim=-1).mean()
    model.condition(q[:500], x[:500])
    assert model.train_u_.shape[0] == 500
    error_500 = (model.predict(q_test) - x_test).norm(dim=-1).mean()
    assert error_1000 <= error_500, (error_1000, error_500)


def test_max_points_keeps_a_seeded_random_subset_and_reports_validation():
    q, x = toy_data(300, seed=11)
    steps, metrics = [], {}
    model = GPRModel(TOY.body, "ee_xyz", (3,), max_points=120, hyper_points=60, adam_steps=5, lbfgs_steps=20,
                     kernel="rbf").fit(
        q.numpy(), x.numpy(), seed=3, val=toy_data(40, seed=12), progress=False,
        on_epoch=lambda step, m: (steps.append(step), metrics.update(m)))
    assert model.train_u_.shape == (120, 2)
    assert steps == sorted(steps) and len(steps) >= 6
    assert {"train_neg_mll", "val_mean_error", "val_rmse"} <= set(metrics)
    assert metrics["val_mean_error"] < 1e-2


@pytest.mark.parametrize("case", ["length", "nan", "shape"])
def test_fit_with_bad_data_raises_the_house_error(case):
    q, x = toy_data(20, seed=1)
    if case == "length":
        q, match = q[:-1], "q and x must be of the same length"
    elif case == "nan":
        x[3, 1], match = float("nan"), "x must be finite"
    else:
        x, match = x[:, :2], r"x must be of shape \(N, 3\)"
    with pytest.raises(ValueError, match=match):
        GPRModel(TOY.body, "ee_xyz", (3,)).fit(q, x, progress=False)
    with pytest.raises(TypeError, match="q must be a numpy array or torch.Tensor"):
        GPRModel(TOY.body, "ee_xyz", (3,)).fit(q.tolist(), x, progress=False)


def test_bad_hyper_parameters_raise():
    with pytest.raises(ValueError, match="noise_floor must be > 0"):
        GPRModel(TOY.body, "ee_xyz", (3,), noise_floor=0.0)
    with pytest.raises(ValueError, match="hyper_points must be an integer ≥ 2"):
        GPRModel(TOY.body, "ee_xyz", (3,), hyper_points=1)
