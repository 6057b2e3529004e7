"""Order-0 perception by Levenberg–Marquardt and Adam (aif/descent.py), and F as one function of μ with Π(μ)."""

from __future__ import annotations

import math

import pytest
import torch

from bodyschema.aif.free_energy import sensory_terms
from bodyschema.aif.perception import Perception, PerceptionConfig
from tests.aif.toys import ToyBlobImage, perturb, planar_poses
from tests.toy_models import ToyPlanarArm

DEG = math.pi / 180
METHODS = [PerceptionConfig(method="lm"), PerceptionConfig(method="adam"), PerceptionConfig(method="adam+lm")]
IDS = ["lm", "adam", "adam+lm"]


@pytest.fixture
def arm():
    return ToyPlanarArm()


def _kinematics():
    arm = ToyPlanarArm()
    return arm, "ee_xyz", arm.predict


def _small_decoder():
    """A real pixel decoder (8×12 blob images of the toy arm), run in float64 so that F is exact enough to compare."""
    from tests.models.test_pixel import blob_images, joint_angles, one_thread, tiny_decoder
    q = joint_angles(128, seed=0)
    with one_thread():
        decoder = tiny_decoder().fit(q, blob_images(q), seed=0, progress=False)
    decoder.compute_dtype = torch.float64
    return decoder, "image", decoder.predict


MODELS = [_kinematics, _small_decoder]
MODEL_IDS = ["kinematics", "small-decoder"]


@pytest.mark.parametrize("config", METHODS, ids=IDS)
def test_recovers_true_joints_and_stops_on_its_own(arm, config):
    q = planar_poses(100, seed=0)
    result = Perception([arm], config).infer({"ee_xyz": arm.predict(q)}, perturb(q, seed=1))
    assert (result.mu - q).abs().max() / DEG < 0.1
    assert result.converged.all() and not result.diverged.any()
    assert result.steps.max() < config.max_steps


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("config", METHODS, ids=IDS)
def test_free_energy_never_rises_and_ends_below_the_start(make, config):
    model, modality, predict = make()
    q = planar_poses(64, seed=4)
    result = Perception([model], PerceptionConfig(**{**config.__dict__, "record": True})).infer(
        {modality: predict(q)}, perturb(q, seed=5, max_rad=0.6))
    f = result.trajectory["F"]                                             # (T, B), NaN once a trial stopped
    rises = torch.diff(f, dim=0)
    assert (rises[torch.isfinite(rises)] <= 0).all()
    assert (result.F <= f[0]).all()


@pytest.mark.parametrize("make", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("config", METHODS, ids=IDS)
def test_batched_rows_equal_the_per_trial_loop_in_float64(make, config):
    model, modality, predict = make()
    q = planar_poses(12, seed=6)
    obs, mu0 = {modality: predict(q)}, perturb(q, seed=7, max_rad=0.5)
    perception = Perception([model], config)
    batched = perception.infer(obs, mu0)
    for i in range(len(q)):
        single = perception.infer({modality: obs[modality][i:i + 1]}, mu0[i:i + 1])
        # Rows are independent, but not bit for bit: a batch of 12 and of 1 take other SIMD/BLAS paths (and a
        # convolution another summation order), ≈1e-16 apart per operation, seen up to 1e-15 rad after the descent
        # on kinematics. 1e-12 rad on kinematics, 1e-10 rad through a decoder, far below any effect of coupling.
        atol = 1e-10 if modality == "image" else 1e-12
        assert torch.allclose(single.mu[0], batched.mu[i], rtol=0, atol=atol), (i, single.mu[0] - batched.mu[i])
        assert single.steps[0] == batched.steps[i]


@pytest.mark.parametrize("level", [1, 2])
def test_planar2_levels_recover_poses_from_the_analytic_oracle(level):
    import numpy as np

    from bodyschema.evaluation.core.seeds import eval_rng
    from bodyschema.evaluation.core.specs import load_robot
    from bodyschema.evaluation.levels.targets import initial_beliefs, make_targets
    from bodyschema.models.analytic import AnalyticModel
    model = AnalyticModel("planar2", "ee_xyz")
    robot = load_robot([model])
    targets = make_targets(robot, 200, eval_rng(0, 0, "targets"), False, {}, eval_rng(0, 0, "noise"))
    mu0 = initial_beliefs(level, targets.q, robot.sampling_ranges, eval_rng(0, 0, "beliefs", level))
    for config in METHODS:
        result = Perception([model], config).infer(targets.tensors(["ee_xyz"]), torch.from_numpy(mu0))
        error = np.rad2deg(np.abs(result.mu.numpy() - targets.q)).mean()
        assert error < 0.2, f"{config.method}: level {level} mean joint error {error:.3f}°"


def test_lm_builds_the_image_jacobian_for_its_curvature_and_adam_only_vjps():
    image = ToyBlobImage()
    q = planar_poses(30, seed=24)
    obs, mu0 = {"image": image.predict(q)}, perturb(q, seed=25, max_rad=0.1)
    for config, used, unused in ((METHODS[0], "jacobian", "vjp"), (METHODS[1], "vjp", "jacobian")):   # LM, Adam
        image.calls = {"vjp": 0, "jacobian": 0}
        result = Perception([image], config).infer(obs, mu0)
        assert (result.mu - q).abs().max() / DEG < 0.1, config.method
        assert image.calls[used] > 0 and image.calls[unused] == 0, (config.method, image.calls)


def test_order_above_zero_refuses_lm_and_adam():
    with pytest.raises(ValueError, match="method must be 'flow' when order > 0"):
        PerceptionConfig(method="lm", order=1, prior="damping")
    with pytest.raises(ValueError, match="method must be one of"):
        PerceptionConfig(method="newton")


# ---- F with a precision that depends on μ --------------------------------------------------------------
def _gpr():
    from tests.models.test_gpr import fit_gpr
    return fit_gpr(60)


def _mdn():
    from tests.models.test_mdn import tiny_mdn, toy_data
    q, x = toy_data(256, seed=0)
    model = tiny_mdn().fit(q, x, seed=0, progress=False)
    model.compute_dtype = torch.float64          # F in float64: finite differences of a float32 F are noise
    return model


@pytest.mark.parametrize("make", [_gpr, _mdn], ids=["gpr", "mdn"])
def test_free_energy_gradient_includes_the_precision_term(make):
    """∂F/∂μ equals central differences of F = ½εᵀΠ(μ)ε − ½ln|Π(μ)|, not only of its ε part."""
    model = make()
    q = planar_poses(6, seed=30)
    x = model.predict(q) + 0.01 * torch.randn(6, 3, generator=torch.Generator().manual_seed(31), dtype=q.dtype)
    mu = perturb(q, seed=32, max_rad=0.1)

    def terms(m):
        return sensory_terms([model], {"ee_xyz": x}, {"ee_xyz": None}, m, need_hessian=False)

    step = 1e-4
    fd = torch.zeros_like(mu)
    for d in range(mu.shape[1]):
        shift = torch.zeros_like(mu)
        shift[:, d] = step
        fd[:, d] = (terms(mu + shift).free_energy - terms(mu - shift).free_energy) / (2 * step)
    grad = terms(mu).grad
    rel = (grad - fd).norm() / fd.norm()
    assert rel < 1e-3, f"∂F/∂μ off by {rel:.2e} relative to finite differences of F"
    frozen = grad - model.precision_vjp(mu, 0.5 * (x - model.predict(mu)).pow(2) - 0.5 / model.precision(mu))
    assert (frozen - fd).norm() / fd.norm() > 10 * rel, "the Π(μ) term should matter for this model"


@pytest.mark.parametrize("method", ["lm", "adam+lm"])
def test_lm_with_trial_derivatives_takes_the_same_steps_in_fewer_model_calls(method):
    """Derivatives asked with every trial step: the same F, gradient and H at every accepted belief, so the same
    steps bit for bit (a float64 model), and one model call per LM step instead of F and then the derivatives."""
    from bodyschema.aif.perception_config import LMSettings
    image = ToyBlobImage()
    q = planar_poses(1, seed=26)
    obs, mu0 = {"image": image.predict(q)}, perturb(q, seed=27, max_rad=0.2)
    predict, results, calls = image.predict, [], []

    def counted(z):
        image.calls["predict"] += 1
        return predict(z)

    image.predict = counted
    for trial_derivatives in (False, True):
        image.calls = {"vjp": 0, "jacobian": 0, "predict": 0}
        config = PerceptionConfig(method=method, max_steps=6, lm=LMSettings(trial_derivatives=trial_derivatives))
        results.append(Perception([image], config).infer(obs, mu0))
        calls.append(dict(image.calls))
    torch.testing.assert_close(results[1].mu, results[0].mu, rtol=0, atol=0)
    torch.testing.assert_close(results[1].F, results[0].F, rtol=0, atol=0)
    assert (results[1].steps == results[0].steps).all()
    assert (results[0].mu - q).abs().max() < (mu0 - q).abs().max()
    assert calls[1]["predict"] < calls[0]["predict"], calls            # no second forward at an accepted step
    assert calls[1]["jacobian"] >= calls[0]["jacobian"], "every trial builds its Jacobian (most are accepted)"
