"""`gpr` with the kinematic kernel (models/_gp_trig.py): the shared contract on the toy arm, its marginal-likelihood
gradient, its exactness on a 7-joint arm, and the `auto` choice between it and the RBF."""

import numpy as np
import pytest
import torch

from bodyschema.datagen.body.robot import Robot
from bodyschema.models import _gp_trig
from bodyschema.models.analytic import AnalyticModel
from bodyschema.models.gpr import GPRModel
from bodyschema.models.scaling import BodySpec
from tests.models.contract import SensoryModelContract
from tests.models.test_gpr import TOY, fit_gpr, single_thread, toy_data  # noqa: F401 (the fixture applies here too)


class TestGPRKinematic(SensoryModelContract):
    def make_model(self, seed):
        return fit_gpr(200, seed, kernel="kinematic")

    def make_inputs(self, n, dtype=torch.float64):
        return toy_data(n, seed=n)[0].to(dtype)

    def make_unfitted_model(self):
        return GPRModel(TOY.body, "ee_xyz", (3,), kernel="kinematic")

    def test_the_planar_arm_is_learned_exactly(self, model):
        # x, y of a 2-link arm are in the span of the 9 features: 200 poses interpolate it to the noise floor.
        q, x = toy_data(500, seed=7)
        err = (model.predict(q) - x).norm(dim=-1)                                     # (500,) m
        assert err.max() < 1e-6, f"max error {err.max():.2e} m"                      # measured ~1e-8 m
        torch.testing.assert_close(model.jacobian(q), TOY.jacobian(q), rtol=0, atol=1e-5)

    def test_to_gpytorch_is_refused_with_the_house_error(self, model):
        with pytest.raises(ValueError, match="the gpr kernel must be rbf for to_gpytorch"):
            model.to_gpytorch()


def test_the_closed_form_mll_gradient_equals_autograd():
    gen = torch.Generator().manual_seed(3)
    q = torch.rand(40, 3, generator=gen, dtype=torch.float64) * 4 - 2                 # (40, 3) rad
    y = torch.randn(2, 40, generator=gen, dtype=torch.float64)                        # (2, 40)
    theta = torch.tensor([[0.3, 1.5, 0.02, 2.0, 1e-2], [4.0, 0.1, 1.0, 0.5, 1e-3]], dtype=torch.float64).log()
    loss, grad = _gp_trig.neg_mll_and_grad(q, y, *split(theta))

    def reference(theta):                                                              # the kernel, then autograd
        offset, scale, noise = split(theta)
        f = (offset[:, :, None, None] + torch.cos(q.T[:, :, None] - q.T[:, None, :])) / (1 + offset)[:, :, None, None]
        k = scale[:, None, None] * f.prod(1) + noise[:, None, None] * torch.eye(40, dtype=torch.float64)
        return -torch.distributions.MultivariateNormal(torch.zeros(40, dtype=torch.float64), k).log_prob(y)

    theta.requires_grad_(True)
    expected = reference(theta)
    expected.sum().backward()
    torch.testing.assert_close(loss, expected.detach(), rtol=1e-10, atol=1e-9)
    torch.testing.assert_close(grad, theta.grad, rtol=1e-8, atol=1e-9)


def split(theta):
    return theta[:, :-2].exp(), theta[:, -2].exp(), theta[:, -1].exp()


def test_the_shipped_panda_7_joints_from_3000_poses_under_10_micrometres():
    # The RBF kernel is tens of mm off over a 7-joint arm's full ranges at this many poses (README, "nine arms");
    # the kinematic kernel's 3^7 = 2187 features hold the forward kinematics exactly.
    oracle = AnalyticModel("panda", "ee_xyz")
    ranges = torch.tensor(Robot.load("panda").sampling_ranges, dtype=torch.float64)   # (7, 2) rad
    gen = torch.Generator().manual_seed(0)
    q = ranges[:, 0] + torch.rand(3500, 7, generator=gen, dtype=torch.float64) * (ranges[:, 1] - ranges[:, 0])
    x = oracle.predict(q)                                                              # (2800, 3) m
    body = BodySpec("panda", oracle.body.joint_names, *ranges.T.tolist())
    model = GPRModel(body, "ee_xyz", (3,), kernel="kinematic").fit(q[:3000], x[:3000])
    err = (model.predict(q[3000:]) - x[3000:]).norm(dim=-1)                            # (500,) m
    assert err.mean() < 1e-5, f"mean held-out error {err.mean() * 1e3:.2e} mm"        # measured 7.8e-4 mm


def test_auto_keeps_the_kernel_of_higher_marginal_likelihood():
    q, x = toy_data(200, seed=5)
    assert GPRModel(TOY.body, "ee_xyz", (3,)).fit(q, x).kernel_ == "kinematic"
    # a Gaussian bump, which no trig polynomial of degree one per joint holds: the RBF explains it (measured 3e-5
    # mean error against 0.08 for the kinematic kernel)
    bump = torch.exp(-((q - 0.3) ** 2).sum(-1, keepdim=True) / 1.0).expand(-1, 3).contiguous()
    assert GPRModel(TOY.body, "ee_xyz", (3,)).fit(q, bump).kernel_ == "rbf"


def test_kinematic_refuses_eight_joints_and_auto_falls_back_to_rbf():
    body = BodySpec("eight", tuple(f"j{i}" for i in range(8)), (-1.0,) * 8, (1.0,) * 8)
    with pytest.raises(ValueError, match='kernel "kinematic" must be used with at most 7 joints'):
        GPRModel(body, "ee_xyz", (3,), kernel="kinematic")
    with pytest.raises(ValueError, match="kernel must be one of"):
        GPRModel(body, "ee_xyz", (3,), kernel="trig")
    q = torch.rand(60, 8, generator=torch.Generator().manual_seed(1), dtype=torch.float64) * 2 - 1
    model = GPRModel(body, "ee_xyz", (3,), hyper_points=30).fit(q, q[:, :3].sin())
    assert model.kernel_ == "rbf"


def test_the_feature_form_likelihood_on_all_poses_equals_the_kernel_form():
    # refine_on_all_poses optimizes s and σ² through M's eigendecomposition (Woodbury, determinant lemma): its −MLL
    # must be the kernel form's, here with more features (27) than poses (20) and the other way round (60).
    gen = torch.Generator().manual_seed(8)
    for n in (20, 60):
        q = torch.rand(n, 3, generator=gen, dtype=torch.float64) * 4 - 2
        y = torch.randn(1, n, generator=gen, dtype=torch.float64)
        offset, scale, noise = torch.tensor([[0.4, 2.0, 1.0]], dtype=torch.float64), 1.7, 0.03
        root = _gp_trig.prior_weights(offset, torch.ones(1, dtype=torch.float64)).sqrt()[0]     # (27,)
        phi = _gp_trig.features(q)
        e, v = torch.linalg.eigh(root[:, None] * (phi.T @ phi) * root[None, :])
        b2 = (v.T @ (root * (y[0] @ phi))).pow(2)
        objective = _gp_trig._scale_noise_mll(e.clamp_min(0).numpy(), b2.numpy(), float(y[0] @ y[0]), n)
        loss, grad = objective(np.log([scale, noise]))
        expected, expected_grad = _gp_trig.neg_mll_and_grad(q, y, offset, torch.tensor([scale], dtype=torch.float64),
                                                            torch.tensor([noise], dtype=torch.float64))
        assert loss + 0.5 * n * np.log(2 * np.pi) == pytest.approx(float(expected[0]), rel=1e-9)
        np.testing.assert_allclose(grad, expected_grad[0, -2:].numpy(), rtol=1e-7)


def test_the_kinematic_kernel_is_conditioned_on_every_pose_past_max_points(monkeypatch):
    # max_points bounds the RBF's n×n matrices; the feature form's cost is O(n·9^D) time and O(9^D) memory, summed in
    # blocks (CHUNK, made small here to cross block boundaries): all 300 poses are kept, and blocks change nothing
    monkeypatch.setattr(_gp_trig, "CHUNK", 64)
    q, x = toy_data(300, seed=11)
    model = GPRModel(TOY.body, "ee_xyz", (3,), max_points=120, hyper_points=60, kernel="kinematic").fit(q, x)
    assert model.train_u_.shape == (300, 2)
    gram, phi_y = _gp_trig.moments(q, x.T)
    phi = _gp_trig.features(q)
    torch.testing.assert_close(gram, phi.T @ phi, rtol=1e-12, atol=1e-9)
    torch.testing.assert_close(phi_y, x.T @ phi, rtol=1e-12, atol=1e-9)
    model.condition(q[:200], x[:200])
    assert model.train_u_.shape == (200, 2)


def test_the_model_card_says_which_kernel_auto_chose():
    from bodyschema.training.model_card import model_summary

    q, x = toy_data(120, seed=6)
    chosen = GPRModel(TOY.body, "ee_xyz", (3,), hyper_points=60).fit(q, x)
    assert model_summary(chosen).endswith("Kernel kinematic: the likelier of rbf and kinematic.")
    assert "Kernel" not in model_summary(GPRModel(TOY.body, "ee_xyz", (3,), kernel="rbf", hyper_points=60).fit(q, x))


def test_the_ee_orientation_is_held_exactly_and_its_jacobian_is_the_oracles():
    # Each entry of the ee's rotation matrix is, like ee_xyz, of degree one in each joint's (cos q, sin q).
    oracle = AnalyticModel("nao_arm", "ee_rot")
    ranges = torch.tensor(Robot.load("nao_arm").sampling_ranges, dtype=torch.float64)   # (4, 2) rad
    gen = torch.Generator().manual_seed(1)
    q = ranges[:, 0] + torch.rand(700, 4, generator=gen, dtype=torch.float64) * (ranges[:, 1] - ranges[:, 0])
    body = BodySpec("nao_arm", oracle.body.joint_names, *ranges.T.tolist())
    model = GPRModel(body, "ee_rot", (9,)).fit(q[:600], oracle.predict(q[:600]), progress=False)
    assert model.kernel_ == "kinematic"
    held_out = q[600:]
    assert (model.predict(held_out) - oracle.predict(held_out)).abs().max() < 1e-4   # a degree is 0.0175
    torch.testing.assert_close(model.jacobian(held_out), oracle.jacobian(held_out), atol=1e-3, rtol=0)
