"""Perception on the closed-form planar arm: recovery, F descent, fusion, broken sensors, divergence, batching."""

from __future__ import annotations

import math

import pytest
import torch

from bodyschema.aif.flow import DESCENT_SLACK
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from tests.aif.toys import ToyJoints, other_robot_joints, perturb, planar_poses
from tests.toy_models import ToyPlanarArm

DEG = math.pi / 180


@pytest.fixture
def arm():
    return ToyPlanarArm()


@pytest.mark.parametrize("config", [PerceptionConfig(), PerceptionConfig(order=1, prior="damping"),
                                    PerceptionConfig(order=2, prior="damping"),
                                    PerceptionConfig(flow=FlowSettings(integrator="implicit"))],
                         ids=["n0", "n1-damping", "n2-damping", "n0-implicit"])
def test_recovers_true_joints_from_perturbed_belief(arm, config):
    q = planar_poses(100, seed=0)
    result = Perception([arm], config).infer({"ee_xyz": arm.predict(q)}, perturb(q, seed=1))
    error_deg = (result.mu - q).abs().max() / DEG
    assert error_deg < 0.1, f"max joint error {error_deg:.3g}°"
    assert result.converged.all() and not result.diverged.any()
    assert result.steps.max() < 50, "the local-linear update should converge in tens of steps"


def test_plain_euler_protocol_also_recovers(arm):
    q = planar_poses(50, seed=2)
    config = PerceptionConfig(flow=FlowSettings(integrator="euler", dt=0.1, k_z=1e-3), max_steps=3000, tol=0.0,
                              max_step=None)
    result = Perception([arm], config).infer({"ee_xyz": arm.predict(q)}, perturb(q, seed=3))
    assert (result.mu - q).abs().max() / DEG < 0.1


@pytest.mark.parametrize("integrator", ["local_linear", "euler"])
def test_free_energy_decreases_along_the_trajectory(arm, integrator):
    q = planar_poses(64, seed=4)
    config = PerceptionConfig(flow=FlowSettings(integrator=integrator,
                                                **({"dt": 0.1, "k_z": 1e-3} if integrator == "euler" else {})),
                              record=True, max_steps=300)
    result = Perception([arm], config).infer({"ee_xyz": arm.predict(q)}, perturb(q, seed=5))
    f = result.trajectory["F"]                                             # (T, B), NaN once a trial stopped
    steps = torch.diff(f, dim=0)
    rises = steps[torch.isfinite(steps)]
    assert (rises <= 1e-9 * f[0].abs().max()).all(), f"F rose by up to {rises.max():.3g}"
    assert (result.F < f[0]).all()


def test_fusion_of_two_noisy_sensors_beats_each_alone(arm):
    q = planar_poses(300, seed=6)
    g = torch.Generator().manual_seed(7)
    ee_noise, joint_noise = 0.01, 2 * DEG                                   # m, rad (standard deviations)
    x_ee = arm.predict(q) + ee_noise * torch.randn(q.shape[0], 3, generator=g, dtype=q.dtype)
    x_ee[:, 2] = 0.0
    x_q = q + joint_noise * torch.randn(q.shape, generator=g, dtype=q.dtype)
    ee, joints = ToyPlanarArm(precision=ee_noise ** -2), ToyJoints(precision=joint_noise ** -2)
    mu0 = perturb(q, seed=8)

    def error(models, obs):
        return (Perception(models).infer(obs, mu0).mu - q).pow(2).mean().sqrt()

    fused = error([ee, joints], {"ee_xyz": x_ee, "joints": x_q})
    assert fused < error([ee], {"ee_xyz": x_ee})
    assert fused < error([joints], {"joints": x_q})


def test_zero_precision_modality_is_ignored(arm):
    q = planar_poses(40, seed=9)
    mu0 = perturb(q, seed=10)
    alone = Perception([arm]).infer({"ee_xyz": arm.predict(q)}, mu0)
    garbage = {"ee_xyz": arm.predict(q), "joints": torch.full_like(q, 2.0)}
    broken = Perception([arm, ToyJoints()], precisions={"joints": 0.0})
    torch.testing.assert_close(broken.infer(garbage, mu0).mu, alone.mu, rtol=0, atol=1e-12)
    omitted = broken.infer({"ee_xyz": arm.predict(q)}, mu0)               # a broken sensor needs no observation
    torch.testing.assert_close(omitted.mu, alone.mu, rtol=0, atol=1e-12)


def test_absurd_dt_marks_trials_diverged_and_the_run_goes_on(arm):
    q = planar_poses(6, seed=11)
    precision = torch.tensor([1e4, 1e4, 1e4, 1e-8, 1e-8, 1e-8], dtype=torch.float64)[:, None].expand(6, 3)
    config = PerceptionConfig(flow=FlowSettings(integrator="euler", dt=1e6, k_z=1.0, step_control="none"),
                              max_steps=50, max_step=None)
    result = Perception([arm], config, precisions={"ee_xyz": precision}).infer({"ee_xyz": arm.predict(q)},
                                                                                perturb(q, seed=12))
    assert result.diverged[:3].all() and (result.diverged_step[:3] == 0).all()
    assert result.n_diverged == 3
    assert not result.diverged[3:].any() and (result.diverged_step[3:] == -1).all()
    assert torch.isfinite(result.mu).all(), "a diverged trial keeps its last finite belief"


def test_descent_step_control_never_raises_F_and_tames_an_absurd_euler_step(arm):
    q = planar_poses(32, seed=21)
    mu0 = perturb(q, seed=22)
    obs = {"ee_xyz": arm.predict(q)}
    wild = dict(integrator="euler", dt=1e3, k_z=1.0)

    def config(control):
        return PerceptionConfig(flow=FlowSettings(**wild, step_control=control), max_steps=400, max_step=None,
                                record=True)

    plain = Perception([arm], config("none")).infer(obs, mu0)
    assert plain.diverged.all(), "without step control this Euler step must blow up"
    result = Perception([arm], config("descent")).infer(obs, mu0)
    f = result.trajectory["F"]                                             # (T, B) at the accepted beliefs
    rises = torch.diff(f, dim=0) - DESCENT_SLACK * f[:-1].abs()           # the float32 allowance of a model
    assert (rises[torch.isfinite(rises)] <= 0).all(), "an accepted step never raises F"
    assert not result.diverged.any() and result.converged.all()
    assert (result.F < f[0]).all()


def test_descent_step_control_matches_the_plain_update_where_every_step_descends(arm):
    q = planar_poses(16, seed=23)
    mu0 = perturb(q, seed=24)
    obs = {"ee_xyz": arm.predict(q)}
    plain = Perception([arm], PerceptionConfig(flow=FlowSettings(step_control="none"))).infer(obs, mu0)
    descent = Perception([arm], PerceptionConfig(flow=FlowSettings(step_control="descent"))).infer(obs, mu0)
    assert (descent.mu - q).abs().max() < 0.1 * DEG and (plain.mu - q).abs().max() < 0.1 * DEG
    assert descent.converged.all()


@pytest.mark.parametrize("config", [PerceptionConfig(order=1, prior="damping"),
                                    PerceptionConfig(flow=FlowSettings(integrator="euler", dt=1e3,
                                                                       step_control="descent"), max_step=None)],
                         ids=["n1-damping", "euler-descent"])
def test_batched_result_equals_per_trial_loop(arm, config):
    q = planar_poses(12, seed=13)
    mu0 = perturb(q, seed=14)
    perception = Perception([arm, ToyJoints()], config)
    obs = {"ee_xyz": arm.predict(q), "joints": q + 0.01}
    batched = perception.infer(obs, mu0)
    for i in range(q.shape[0]):
        single = perception.infer({k: v[i:i + 1] for k, v in obs.items()}, mu0[i:i + 1])
        torch.testing.assert_close(single.mu[0], batched.mu[i], rtol=0, atol=1e-12)
        assert single.steps[0] == batched.steps[i]
        torch.testing.assert_close(single.F[0], batched.F[i], rtol=1e-12, atol=1e-9)


def test_belief_stays_inside_given_limits(arm):
    q = planar_poses(20, seed=15)
    perception = Perception([arm], limits=((-0.2, 0.1), (0.2, 1.0)))
    mu = perception.infer({"ee_xyz": arm.predict(q)}, torch.zeros_like(q)).mu
    assert (mu[:, 0] >= -0.2).all() and (mu[:, 0] <= 0.2).all()
    assert (mu[:, 1] >= 0.1).all() and (mu[:, 1] <= 1.0).all()


def test_attractor_prior_pulls_belief_to_the_goal(arm):
    goal_q = planar_poses(10, seed=16)
    config = PerceptionConfig(order=1, prior="attractor", prior_precision=1.0, attractor_gain=10.0, max_steps=300)
    perception = Perception([arm], config, precisions={"ee_xyz": 0.0})   # no sensing: intention only
    result = perception.infer({}, perturb(goal_q, seed=17), goal={"ee_xyz": arm.predict(goal_q)})
    reached = (arm.predict(result.mu) - arm.predict(goal_q)).norm(dim=-1)
    assert reached.max() < 1e-4, f"end effector {reached.max():.3g} m from the goal"


def test_trajectory_is_recorded_with_nan_after_a_trial_stops(arm):
    q = planar_poses(5, seed=18)
    result = Perception([arm], PerceptionConfig(record=True)).infer({"ee_xyz": arm.predict(q)}, perturb(q, 19))
    traj = result.trajectory
    t = traj["F"].shape[0]
    assert traj["mu"].shape == (t, 5, 1, 2) and traj["error:ee_xyz"].shape == (t, 5)
    for i in range(5):
        assert torch.isfinite(traj["F"][: result.steps[i], i]).all()
        assert torch.isnan(traj["F"][result.steps[i]:, i]).all()


# ---- errors at the edge ---------------------------------------------------------------------------------
def test_wrong_observation_shape_raises(arm):
    q = planar_poses(4, seed=20)
    with pytest.raises(ValueError, match=r"observations\['ee_xyz'\] must be a tensor of shape \(4, 3\)"):
        Perception([arm]).infer({"ee_xyz": arm.predict(q)[:, :2]}, q)


def test_unknown_or_missing_modality_raises(arm):
    q = planar_poses(4, seed=21)
    with pytest.raises(ValueError, match="observations keys must be"):
        Perception([arm]).infer({"ee_xyz": arm.predict(q), "image": q}, q)
    with pytest.raises(ValueError, match="must be present"):
        Perception([arm, ToyJoints()]).infer({"ee_xyz": arm.predict(q)}, q)


def test_models_of_another_body_raise(arm):
    with pytest.raises(ValueError, match="body must be robot 'toy_planar'"):
        Perception([arm, other_robot_joints()])


def test_bad_mu0_and_config_raise(arm):
    with pytest.raises(ValueError, match="mu0 must be"):
        Perception([arm]).infer({"ee_xyz": torch.zeros(3, 3, dtype=torch.float64)}, torch.zeros(3, 5))
    with pytest.raises(ValueError, match="order must be 0, 1 or 2"):
        PerceptionConfig(order=3)
    with pytest.raises(ValueError, match="step_control must be 'none' when order > 0"):
        PerceptionConfig(order=1, flow=FlowSettings(step_control="descent"))
    with pytest.raises(ValueError, match="precision override key must be"):
        Perception([arm], precisions={"image": 1.0})


def test_unstable_update_bouncing_between_limits_is_flagged_diverged(arm):
    q = planar_poses(50, seed=22)                                          # Euler with Δt·λ_max ≈ 30: unstable,
    config = PerceptionConfig(flow=FlowSettings(integrator="euler", dt=0.01, step_control="none"),   # steps stay
                              max_steps=300, max_step=None)                                        # < 1e3 rad
    result = Perception([arm], config).infer({"ee_xyz": arm.predict(q)}, perturb(q, seed=23))
    assert result.n_diverged > 25 and not (result.converged & result.diverged).any()
    assert (result.diverged_step[result.diverged] < 20).all()


def test_image_model_gradient_uses_vjp_or_the_curvature_jacobian_and_recovers_the_joints():
    from tests.aif.toys import ToyBlobImage
    image = ToyBlobImage()
    q = planar_poses(30, seed=24)
    obs, mu0 = {"image": image.predict(q)}, perturb(q, seed=25, max_rad=0.1)
    result = Perception([image], PerceptionConfig(method="flow")).infer(obs, mu0)
    assert (result.mu - q).abs().max() / DEG < 0.1
    assert image.calls["jacobian"] > 0 and image.calls["vjp"] == 0, \
        "the local-linear step builds the image Jacobian (in chunks) for its curvature and takes the gradient from it"
    image.calls = {"vjp": 0, "jacobian": 0}
    Perception([image], PerceptionConfig(method="flow", flow=FlowSettings(integrator="euler", dt=1e-6),
                                         max_steps=5)).infer(obs, mu0)
    assert image.calls == {"vjp": 4, "jacobian": 0}, \
        "Euler never builds the image Jacobian; under descent control the last of 5 evaluations judges F alone"


def test_the_default_step_control_is_descent_at_order_0_and_none_above():
    """As `evaluate levels` (the CLI's perception): monotone descent for static perception; generalized motion
    (order > 0) cannot use it (F is no Lyapunov function of that flow), and needs no opt-out to be valid."""
    assert PerceptionConfig().descends and PerceptionConfig(flow=FlowSettings(step_control="descent")).descends
    assert not PerceptionConfig(order=1, prior="damping").descends
    assert not PerceptionConfig(flow=FlowSettings(step_control="none")).descends
