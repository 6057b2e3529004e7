"""`sklearn_gpr` (scikit-learn baseline): the shared contract on the toy arm, plus accuracy and fit errors."""

import numpy as np
import pytest
import torch

from bodyschema.models.sklearn_gpr import SklearnGPRModel
from tests.models.contract import SensoryModelContract
from tests.models.test_gpr import TOY, single_thread, toy_data  # noqa: F401 — fixtures, used by name


def fit_sk(n: int, seed: int = 0, **hyper) -> SklearnGPRModel:
    q, x = toy_data(n, seed=100 + seed)
    return SklearnGPRModel(TOY.body, "ee_xyz", (3,), **hyper).fit(q, x, seed=seed, progress=False)


class TestSklearnGPR(SensoryModelContract):
    def make_model(self, seed):
        return fit_sk(200, seed)

    def make_inputs(self, n, dtype=torch.float64):
        return toy_data(n, seed=n)[0].to(dtype)

    def make_unfitted_model(self):
        return SklearnGPRModel(TOY.body, "ee_xyz", (3,))

    # ---- sklearn_gpr-specific check on the same cached model -------------------------------------------
    def test_held_out_error_and_jacobian_match_the_true_arm(self, model):
        q, x = toy_data(500, seed=7)
        err = (model.predict(q) - x).norm(dim=-1)                                     # (500,) m
        assert err.mean() < 1e-4, f"mean error {err.mean():.2e} m"                    # measured 3.2e-5 m
        jac_rmse = (model.jacobian(q) - TOY.jacobian(q)).pow(2).mean().sqrt()
        assert jac_rmse < 1e-3, f"Jacobian RMSE {jac_rmse:.2e} m/rad"                # measured 2.2e-4 m/rad


def test_precision_is_one_over_sklearn_predictive_variance():
    model = fit_sk(120, max_points=100)
    assert model.regressor_.X_train_.shape == (100, 2)
    z = toy_data(4, seed=8)[0]
    _, std = model.regressor_.predict(TOY.body.to_unit(z).numpy(), return_std=True)   # (4, 3) m
    np.testing.assert_allclose(model.precision(z).numpy(), 1.0 / std**2, rtol=1e-12)


def test_fit_reports_steps_and_validation():
    steps, metrics = [], {}
    q, x = toy_data(80, seed=2)
    SklearnGPRModel(TOY.body, "ee_xyz", (3,)).fit(
        q, x, val=toy_data(30, seed=3), progress=False, on_epoch=lambda s, m: (steps.append(s), metrics.update(m)))
    assert steps == sorted(steps) and len(steps) >= 3
    assert {"train_neg_lml", "val_mean_error", "val_rmse"} <= set(metrics) and metrics["val_mean_error"] < 1e-2


@pytest.mark.parametrize("case", ["length", "nan"])
def test_fit_with_bad_data_raises_the_house_error(case):
    q, x = toy_data(20, seed=1)
    if case == "length":
        x, match = x[:-2], "q and x must be of the same length"
    else:
        x[0, 0], match = float("inf"), "x must be finite"
    with pytest.raises(ValueError, match=match):
        SklearnGPRModel(TOY.body, "ee_xyz", (3,)).fit(q, x, progress=False)
