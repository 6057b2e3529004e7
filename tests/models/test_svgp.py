"""`svgp` (sparse variational GP): the shared contract on the toy arm, the minibatch q(u) kept as trained, the
closed form against the exact GP, seeded determinism, ONNX export. Tiny fits (a few hundred poses, 1 thread)."""

import numpy as np
import pytest
import torch

from bodyschema.models.gpr import GPRModel
from bodyschema.models.svgp import SVGPModel
from tests.models.contract import FD_RTOL, SensoryModelContract
from tests.models.test_gpr import single_thread, toy_data  # noqa: F401  (the fixture: one thread, as gpr's tests)
from tests.toy_models import ToyPlanarArm

TOY = ToyPlanarArm()
SMALL = dict(num_inducing=40, hyper_points=100, elbo_epochs=1, batch_size=64)   # 300 poses: 5 minibatch steps
# The sparse mean is a difference of large terms: its float64 value carries ~1e-10 relative rounding noise, which a
# central difference divides by its step. Measured on 2026-11-29's AMD CPU (the toy fit, seed 0): relative error
# against the closed-form Jacobian 1.1e-4 at a 1e-6 step (the contract's, over its 1e-4 bound: the noise), 1.3e-6 at
# 1e-4, 2.0e-7 at 1e-3 (the truncation error). 1e-4 keeps the noise ~100x under the bound on any CPU.
SVGP_FD_STEP = 1e-4


def fit_svgp(n: int = 300, seed: int = 0, **hyper) -> SVGPModel:
    q, x = toy_data(n, seed=100)
    return SVGPModel(TOY.body, "ee_xyz", (3,), **{**SMALL, **hyper}).fit(q, x, seed=seed)


def held_out_error(model, n: int = 500) -> float:
    q, x = toy_data(n, seed=7)
    return float((model.predict(q) - x).norm(dim=-1).mean())                     # m


class TestSVGP(SensoryModelContract):
    fd_step = SVGP_FD_STEP

    def make_model(self, seed):
        return fit_svgp(seed=seed)

    def make_inputs(self, n, dtype=torch.float64):
        return toy_data(n, seed=n)[0].to(dtype)

    def make_unfitted_model(self):
        return SVGPModel(TOY.body, "ee_xyz", (3,))

    def test_predict_with_jacobian_equals_the_separate_calls(self, model):
        z = toy_data(7, seed=13)[0]
        mean, jac = model.predict_with_jacobian(z)
        torch.testing.assert_close(mean, model.predict(z), rtol=0, atol=1e-10)     # m; Σ order differs
        torch.testing.assert_close(jac, model.jacobian(z), rtol=0, atol=0)

    def test_another_seed_gives_another_model(self, model):
        z = self.make_inputs(5)
        assert not torch.equal(fit_svgp(seed=1).predict(z), model.predict(z))

    def test_onnx_export_equals_the_model(self, model, tmp_path):
        pytest.importorskip("onnxruntime")
        from bodyschema.models.onnx_export import export_onnx, verify_onnx

        assert verify_onnx(model, export_onnx(model, tmp_path / "svgp.onnx"), n=9) < 1e-9   # m


def test_the_minibatch_posterior_kept_as_trained_has_a_finite_difference_jacobian_and_a_precision():
    model = fit_svgp(collapse=False, natural_gradient=False, elbo_epochs=2)
    z = toy_data(4, seed=3)[0]
    jac = model.jacobian(z)                                                      # (4, 3, 2)
    fd = torch.stack([(model.predict(z + SVGP_FD_STEP * e) - model.predict(z - SVGP_FD_STEP * e)) / (2 * SVGP_FD_STEP)
                      for e in torch.eye(2, dtype=z.dtype)], -1)
    assert ((jac - fd).norm() / fd.norm()) < FD_RTOL
    assert (model.precision(z) > 0).all() and torch.isfinite(model.precision(z)).all()


def test_inducing_points_at_the_data_give_the_exact_gp():
    # With U = the training poses, Titsias' optimal q(u) is the exact posterior: the sparse model's mean and
    # precision equal those of the exact GP conditioned with its hyper-parameters (up to the K_uu jitter).
    q, x = toy_data(120, seed=100)
    sparse = SVGPModel(TOY.body, "ee_xyz", (3,), num_inducing=120, inducing_init="random", hyper_points=120,
                       elbo_epochs=0, noise_floor=1e-6).fit(q, x)
    exact = GPRModel(TOY.body, "ee_xyz", (3,), noise_floor=1e-6, kernel="rbf")
    exact.kernel_ = "rbf"
    for key in ("lengthscale", "outputscale", "noise", "y_mean", "y_std"):
        setattr(exact, f"{key}_", getattr(sparse, f"{key}_"))
    exact._condition_unit(TOY.body.to_unit(q), ((x - sparse.y_mean_) / sparse.y_std_).T.contiguous())
    z = toy_data(50, seed=7)[0]
    torch.testing.assert_close(sparse.predict(z), exact.predict(z), rtol=0, atol=1e-7)         # m; measured 7e-9
    torch.testing.assert_close(sparse.precision(z), exact.precision(z), rtol=1e-4, atol=0)


def test_enough_k_means_inducing_points_approach_the_exact_gp_on_the_same_poses():
    # 600 noise-free poses: exact gpr on all of them vs 150 k-means inducing points (the same starting kernel, the
    # collapsed q(u), no minibatch epochs): tolerance 3× the exact held-out error (measured 10.2 vs 4.5 µm).
    q, x = toy_data(600, seed=100)
    exact = held_out_error(GPRModel(TOY.body, "ee_xyz", (3,), hyper_points=150, kernel="rbf").fit(q, x))
    sparse = held_out_error(SVGPModel(TOY.body, "ee_xyz", (3,), num_inducing=150, hyper_points=150,
                                      elbo_epochs=0).fit(q, x))
    assert sparse < 3 * exact, f"sparse {sparse * 1e3:.4f} mm vs exact {exact * 1e3:.4f} mm"


def test_bad_hyper_parameters_are_the_house_error():
    with pytest.raises(ValueError, match=r"num_inducing must be an integer ≥ 1\. Got 0"):
        SVGPModel(TOY.body, "ee_xyz", (3,), num_inducing=0)
    with pytest.raises(ValueError, match=r"inducing_init must be 'kmeans' or 'random'"):
        SVGPModel(TOY.body, "ee_xyz", (3,), inducing_init="grid")
    with pytest.raises(ValueError, match=r"lr must be a finite number > 0\. Got inf"):
        SVGPModel(TOY.body, "ee_xyz", (3,), lr=np.inf)
