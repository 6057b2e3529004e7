"""The active inference torque controller: its laws on hand-made cases, integral action, failures, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bodyschema.aif.aic import AICController
from bodyschema.aif.aic_config import AICConfig
from bodyschema.models.contract import BaseSensoryModel
from tests.aif.toys import ToyJoints
from tests.threads import one_thread
from tests.toy_models import ToyPlanarArm

LIMITS = np.array([50.0, 50.0])                     # N·m, 2 joints


@pytest.fixture(autouse=True)
def single_thread():
    """Per-tick tensors are tiny: intra-op threads only add synchronisation (several times slower on 2 cores)."""
    with one_thread():
        yield


class LinearSensor(BaseSensoryModel):
    """x = W z (3 outputs over the toy arm's 2 joints): J = W exactly, precision 1 (overridden by the AIC)."""

    kind = "toy_linear"
    W = torch.tensor([[1.0, 0.5], [-0.3, 2.0], [0.7, 0.0]], dtype=torch.float64)

    def __init__(self):
        super().__init__(ToyPlanarArm().body, "ee_xyz", (3,))

    def _predict(self, z):
        return z @ self.W.T

    def _jacobian(self, z):
        return self.W.expand(z.shape[0], 3, 2).clone()

    def _precision(self, z):
        return torch.ones(z.shape[0], 3, dtype=z.dtype)


def random_case(b: int, seed: int):
    g = np.random.default_rng(seed)
    q, qd, goal = g.uniform(-1, 1, (b, 2)), g.uniform(-0.5, 0.5, (b, 2)), g.uniform(-1, 1, (b, 2))
    return q, qd, goal, {"ee_xyz": torch.from_numpy(g.uniform(-1, 1, (b, 3)))}


# ---- the laws ---------------------------------------------------------------------------------------------
def test_action_law_equals_minus_ka_sum_of_weighted_errors_on_a_hand_made_case():
    cfg = AICConfig(k_a=3.0, pi_q=2.0, pi_qd=0.5, precisions=(("ee_xyz", 4.0),))
    ctrl = AICController([LinearSensor()], cfg, LIMITS)
    q, qd, _, obs = random_case(4, seed=0)
    mu_tilde = torch.from_numpy(np.random.default_rng(1).uniform(-1, 1, (4, 3, 2)))
    q_t, qd_t = torch.from_numpy(q), torch.from_numpy(qd)
    eps_x = obs["ee_xyz"] - mu_tilde[:, 0] @ LinearSensor.W.T                  # (4, 3)
    # −k_a Σ (∂x/∂u)ᵀ Π ε with ∂q/∂u = ∂q̇/∂u = I and ∂x/∂u = W
    expected = -3.0 * (2.0 * (q_t - mu_tilde[:, 0]) + 0.5 * (qd_t - mu_tilde[:, 1]) + 4.0 * eps_x @ LinearSensor.W)
    torch.testing.assert_close(ctrl.action_rate(mu_tilde, q_t, qd_t, obs), expected)


def test_act_integrates_the_action_law_at_the_updated_belief_and_clips_to_the_limits():
    ctrl = AICController([LinearSensor()], AICConfig(precisions=(("ee_xyz", 4.0),)), LIMITS)
    q, qd, goal, obs = random_case(5, seed=2)
    ctrl.reset(q, qd, {"joints": torch.from_numpy(goal)})
    dt = 0.002
    torque = ctrl.act(q, qd, obs, dt)                                          # the torque starts at 0
    rate = ctrl.action_rate(ctrl.mu_tilde, torch.from_numpy(q), torch.from_numpy(qd), obs)
    np.testing.assert_allclose(torque, np.clip(dt * rate.numpy(), -LIMITS, LIMITS), rtol=1e-12)
    stiff = AICController([], AICConfig(k_a=1e9), LIMITS)
    stiff.reset(q, qd, {"joints": torch.from_numpy(goal)})
    np.testing.assert_array_equal(np.abs(stiff.act(q + 0.1, qd, {}, dt)), np.broadcast_to(LIMITS, q.shape))


def test_euler_belief_step_is_the_aic_papers_update_for_a_joints_goal():
    cfg = AICConfig(k_mu=7.0, pi_q=1.5, pi_qd=0.7, pi_mu=0.4, pi_mu_d=0.2, attractor_gain=1.0, integrator="euler")
    ctrl = AICController([], cfg, LIMITS)
    q0, qd0, goal, _ = random_case(3, seed=3)
    ctrl.reset(q0, qd0, {"joints": torch.from_numpy(goal)})
    q, qd = q0 + 0.05, qd0 - 0.1                                               # the sensors moved
    mu, mu_p, mu_pp, h = q0, qd0, np.zeros_like(q0), 0.01
    # the AIC belief update (Pezzato et al. 2020; the authors' Panda controller) with f(μ) = μ_d − μ
    d_mu = mu_p - cfg.k_mu * (-cfg.pi_q * (q - mu) + cfg.pi_mu * (mu_p + mu - goal))
    d_mu_p = mu_pp - cfg.k_mu * (-cfg.pi_qd * (qd - mu_p) + cfg.pi_mu * (mu_p + mu - goal)
                                 + cfg.pi_mu_d * (mu_pp + mu_p))
    d_mu_pp = -cfg.k_mu * cfg.pi_mu_d * (mu_pp + mu_p)
    ctrl.act(q, qd, {}, h)
    expected = np.stack([mu + h * d_mu, mu_p + h * d_mu_p, mu_pp + h * d_mu_pp], axis=1)
    np.testing.assert_allclose(ctrl.mu_tilde.numpy(), expected, rtol=1e-12, atol=1e-14)


def test_goal_through_an_extra_model_is_the_attractor_beta_jt_residual():
    cfg = AICConfig(k_mu=5.0, pi_q=1.2, pi_qd=0.8, pi_mu=0.6, pi_mu_d=0.3, goal_gains=(("ee_xyz", 3.0),),
                    precisions=(("ee_xyz", 2.0),), integrator="euler")
    ctrl = AICController([LinearSensor()], cfg, LIMITS)
    q, qd, _, obs = random_case(3, seed=9)
    x_d = np.random.default_rng(10).uniform(-1, 1, (3, 3))
    ctrl.reset(q, qd, {"ee_xyz": torch.from_numpy(x_d)})
    h, w, x = 0.01, LinearSensor.W.numpy(), obs["ee_xyz"].numpy()
    mu, mu_p, mu_pp = q, qd, np.zeros_like(q)
    f, a = 3.0 * (x_d - mu @ w.T) @ w, -3.0 * w.T @ w                          # f = β Wᵀ(x_d − Wμ), A = −β WᵀW
    eps_mu, eps_mu_p = mu_p - f, mu_pp - mu_p @ a.T
    grad = -1.2 * (q - mu) - 2.0 * (x - mu @ w.T) @ w - 0.6 * eps_mu @ a       # ∂F/∂μ (Aᵀ applied on the right)
    grad_p = -0.8 * (qd - mu_p) + 0.6 * eps_mu - 0.3 * eps_mu_p @ a
    grad_pp = 0.3 * eps_mu_p
    ctrl.act(q, qd, obs, h)
    expected = np.stack([mu + h * (mu_p - 5.0 * grad), mu_p + h * (mu_pp - 5.0 * grad_p), mu_pp - h * 5.0 * grad_pp], 1)
    np.testing.assert_allclose(ctrl.mu_tilde.numpy(), expected, rtol=1e-12, atol=1e-14)


def test_implicit_belief_step_tends_to_euler_as_dt_shrinks():
    q, qd, goal, _ = random_case(3, seed=4)
    gaps = []
    for h in (1e-2, 1e-3):
        beliefs = []
        for integrator in ("euler", "implicit"):
            ctrl = AICController([], AICConfig(integrator=integrator), LIMITS)
            ctrl.reset(q, qd, {"joints": torch.from_numpy(goal)})
            ctrl.act(q + 0.1, qd, {}, h)
            beliefs.append(ctrl.mu_tilde.numpy())
        gaps.append(np.abs(beliefs[0] - beliefs[1]).max())
    assert gaps[1] < gaps[0] / 50, f"the gap should shrink as dt² (got {gaps})"


@pytest.mark.parametrize("extra", [False, True], ids=["joints", "joints+linear"])
def test_integral_action_rejects_an_unmodelled_constant_torque(extra):
    """A unit-inertia plant pulled by a constant torque (gravity the controller does not know): the AIC's
    integrated action absorbs it and q reaches the goal, where a PD with the same stiffness keeps an offset."""
    dt, disturbance, goal = 0.002, np.array([[-8.0, 5.0]]), np.array([[0.4, -0.3]])
    models = [LinearSensor()] if extra else []
    ctrl = AICController(models, AICConfig(precisions=(("ee_xyz", 0.2),)), LIMITS)
    q, qd = np.zeros((1, 2)), np.zeros((1, 2))
    ctrl.reset(q, qd, {"joints": torch.from_numpy(goal)})
    for _ in range(int(6.0 / dt)):
        obs = {"ee_xyz": torch.from_numpy(q @ LinearSensor.W.numpy().T)} if extra else {}
        qdd = ctrl.act(q, qd, obs, dt) + disturbance - 1.0 * qd               # joint damping 1 N·m·s/rad
        qd = qd + dt * qdd                                                     # semi-implicit Euler plant
        q = q + dt * qd
    assert np.abs(q - goal).max() < 1e-3, f"final error {np.abs(q - goal).max():.2e} rad"
    pd_offset = np.abs(disturbance / ctrl.config.k_a / ctrl.config.pi_qd).max()   # K_p = κ_a Π_q̇
    assert pd_offset > 10 * np.abs(q - goal).max()
    assert not ctrl.failed.any()


# ---- failures inside a running episode ----------------------------------------------------------------------
def test_a_nan_observation_fails_only_that_episode():
    q, qd, goal, obs = random_case(3, seed=5)
    runs = {}
    for poisoned in (False, True):
        ctrl = AICController([LinearSensor()], AICConfig(precisions=(("ee_xyz", 4.0),)), LIMITS)
        ctrl.reset(q, qd, {"joints": torch.from_numpy(goal)})
        torques = []
        for t in range(5):
            x = {"ee_xyz": obs["ee_xyz"].clone()}
            if poisoned and t == 2:
                x["ee_xyz"][1, 0] = float("nan")
            torques.append(ctrl.act(q, qd, x, 0.002))
        runs[poisoned] = (np.array(torques), ctrl)
    torques, ctrl = runs[True]
    assert ctrl.failed.tolist() == [False, True, False]
    assert ctrl.reasons[0] is None and "non-finite ee_xyz" in ctrl.reasons[1]
    assert (torques[2:, 1] == 0).all() and np.isfinite(torques).all()
    np.testing.assert_array_equal(torques[:, [0, 2]], runs[False][0][:, [0, 2]])   # the others go on unchanged


def test_nan_in_the_joint_sensor_fails_the_episode_and_a_broken_sensor_is_ignored():
    q, qd, goal, obs = random_case(2, seed=6)
    ctrl = AICController([LinearSensor()], AICConfig(precisions=(("ee_xyz", 0.0),)), LIMITS)   # broken: Π = 0
    ctrl.reset(q, qd, {"joints": torch.from_numpy(goal)})
    ctrl.act(q, qd, {"ee_xyz": torch.full((2, 3), float("nan"))}, 0.002)
    ctrl.act(q, qd, {}, 0.002)                                                 # a broken sensor may be absent
    assert not ctrl.failed.any()
    bad_q = q.copy()
    bad_q[0, 1] = np.inf
    ctrl.act(bad_q, qd, {}, 0.002)
    assert ctrl.failed.tolist() == [True, False] and "non-finite q" in ctrl.reasons[0]


def test_a_diverging_belief_fails_its_episode():
    q, qd, goal, _ = random_case(2, seed=7)
    ctrl = AICController([], AICConfig(k_mu=1e6, integrator="euler"), LIMITS)  # Euler far beyond its stability
    ctrl.reset(q, qd, {"joints": torch.from_numpy(goal)})
    for _ in range(30):
        torque = ctrl.act(q, qd, {}, 0.01)
    assert ctrl.failed.all() and all("diverged" in r for r in ctrl.reasons)
    assert (torque == 0).all() and np.isfinite(ctrl.belief).all()


# ---- bad input ---------------------------------------------------------------------------------------------
def test_bad_input_raises_the_house_error():
    with pytest.raises(ValueError, match="torque_limits"):
        AICController([], AICConfig(), np.array([1.0, -1.0]))
    with pytest.raises(ValueError, match="models"):                            # a 2-joint model for a 7-joint arm
        AICController([ToyPlanarArm()], AICConfig(), np.full(7, 87.0))
    with pytest.raises(ValueError, match="joints sensor is built in"):
        AICController([ToyJoints()], AICConfig(), LIMITS)
    with pytest.raises(ValueError, match="k_a"):
        AICConfig(k_a=-1.0)
    ctrl = AICController([LinearSensor()], AICConfig(), LIMITS)
    q, qd, goal, obs = random_case(2, seed=8)
    with pytest.raises(RuntimeError, match="before reset"):
        ctrl.act(q, qd, obs, 0.002)
    with pytest.raises(ValueError, match="goal"):
        ctrl.reset(q, qd, {"ee_pixel": torch.zeros(2, 2)})
    ctrl.reset(q, qd, {"ee_xyz": torch.zeros(2, 3)})                           # a goal through the extra model
    with pytest.raises(ValueError, match="observations keys"):
        ctrl.act(q, qd, {}, 0.002)
    with pytest.raises(ValueError, match=r"observations\['ee_xyz'\]"):
        ctrl.act(q, qd, {"ee_xyz": torch.zeros(2, 2)}, 0.002)
    with pytest.raises(ValueError, match="dt"):
        ctrl.act(q, qd, obs, 0.0)
    with pytest.raises(ValueError, match="qd"):
        ctrl.act(q, qd[:1], obs, 0.002)
