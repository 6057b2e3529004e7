"""Action by free-energy descent: the law, the velocity controller's closed loop on a kinematic arm, failures;
the goal attractor: its drift and gradient against finite differences at orders 0–2, its geometry, image goals by
VJP."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from bodyschema.aif.action import ActionConfig, VelocityController, action_rate
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.aif.priors import attractor, prior_terms
from tests.aif.toys import ToyBlobImage, ToyJoints, other_robot_joints, perturb, planar_poses
from tests.toy_models import ToyPlanarArm

DT = 0.02   # s, control period


def controller(**action) -> VelocityController:
    return VelocityController([ToyPlanarArm(), ToyJoints()], PerceptionConfig(), ActionConfig(**action))


def kinematic_loop(ctl: VelocityController, q: np.ndarray, ticks: int) -> np.ndarray:
    """An ideal velocity-controlled arm: q ← q + a·Δt, sensed exactly. → final q (B, 2) rad"""
    arm = ToyPlanarArm()
    for _ in range(ticks):
        qt = torch.from_numpy(q)
        q = q + DT * ctl.act({"ee_xyz": arm.predict(qt), "joints": qt}, DT)
    return q


def test_action_rate_is_the_hand_computed_law():
    pe = {"a": torch.tensor([[1.0, -2.0]]), "b": torch.tensor([[0.5]])}               # Π ε, (1, O_m)
    sens = {"a": torch.tensor([[[1.0, 0.0, 2.0], [0.0, 3.0, 1.0]]]),                  # ∂x/∂a, (1, O_m, 3)
            "b": torch.tensor([[[4.0, 4.0, 4.0]]])}
    # −k_a Σ (∂x/∂a)ᵀ Π ε = −2 · ([1, −6, 0] + [2, 2, 2])
    expected = torch.tensor([[-6.0, 8.0, -4.0]])
    assert torch.allclose(action_rate(pe, sens, k_a=2.0), expected)


def test_action_rate_rejects_mismatched_inputs():
    with pytest.raises(ValueError, match="sensitivities"):
        action_rate({"a": torch.ones(1, 2)}, {"a": torch.ones(1, 3, 2)}, 1.0)
    with pytest.raises(ValueError, match="same modalities"):
        action_rate({"a": torch.ones(1, 2)}, {"b": torch.ones(1, 2, 2)}, 1.0)


def test_velocity_controller_brings_the_arm_to_an_ee_goal_and_beats_standing_still():
    arm = ToyPlanarArm()
    start, target = planar_poses(6, seed=1).numpy(), planar_poses(6, seed=2).numpy()
    goal = arm.predict(torch.from_numpy(target))                                      # (B, 3) m
    ctl = controller()
    ctl.reset(start, {"ee_xyz": goal})
    q = kinematic_loop(ctl, start.copy(), ticks=150)
    still = (arm.predict(torch.from_numpy(start)) - goal).norm(dim=1)
    final = (arm.predict(torch.from_numpy(q)) - goal).norm(dim=1)
    assert not ctl.failed.any()
    assert (final < 0.01 * still).all()
    assert np.abs(ctl.belief - q).max() < 0.05                                        # belief follows the body


def test_velocity_is_clipped_and_the_leak_damps_the_command():
    start, target = planar_poses(4, seed=3).numpy(), planar_poses(4, seed=4).numpy()
    goal = {"joints": torch.from_numpy(target)}
    peaks = {}
    for leak in (0.0, 20.0):
        ctl = controller(max_velocity=1.0, leak=leak)
        ctl.reset(start, goal)
        q, v_end = start.copy(), None
        for _ in range(250):
            v_end = ctl.act({"ee_xyz": ToyPlanarArm().predict(torch.from_numpy(q)),
                             "joints": torch.from_numpy(q)}, DT)
            assert np.abs(v_end).max() <= 1.0 + 1e-12
            q = q + DT * v_end
        peaks[leak] = np.abs(v_end).max()
    assert peaks[20.0] < 0.1 * peaks[0.0]                                            # undamped: still swinging


def test_nan_observation_fails_only_its_episode():
    start, target = planar_poses(3, seed=5).numpy(), planar_poses(3, seed=6).numpy()
    ctl = controller()
    ctl.reset(start, {"joints": torch.from_numpy(target)})
    x = ToyPlanarArm().predict(torch.from_numpy(start))
    x[1, 0] = float("nan")
    v = ctl.act({"ee_xyz": x, "joints": torch.from_numpy(start)}, DT)
    assert ctl.failed.tolist() == [False, True, False]
    assert "non-finite" in ctl.reasons[1] and "ee_xyz" in ctl.reasons[1]
    assert ctl.reasons[0] is None and ctl.reasons[2] is None
    assert np.all(v[1] == 0) and np.abs(v[[0, 2]]).max() > 0
    q = kinematic_loop(ctl, start.copy(), ticks=100)                                  # the others go on
    assert np.abs(q[[0, 2]] - target[[0, 2]]).max() < 0.01 and not ctl.failed[[0, 2]].any()


def test_a_broken_sensor_can_be_omitted_and_no_longer_drives_action():
    start, target = planar_poses(2, seed=7).numpy(), planar_poses(2, seed=8).numpy()
    ctl = VelocityController([ToyPlanarArm(), ToyJoints()], PerceptionConfig(), ActionConfig(),
                             precisions={"joints": 0.0})
    ctl.reset(start, {"ee_xyz": ToyPlanarArm().predict(torch.from_numpy(target))})
    v = ctl.act({"ee_xyz": ToyPlanarArm().predict(torch.from_numpy(start))}, DT)
    assert np.all(v == 0)                                                             # only "joints" drives


def test_bad_input_raises_the_house_error():
    ctl = controller()
    good = planar_poses(2, seed=9).numpy()
    with pytest.raises(ValueError, match="goal"):
        ctl.reset(good, {"touch": torch.zeros(2, 1)})
    with pytest.raises(ValueError, match=r"goal\['joints'\]"):
        ctl.reset(good, {"joints": torch.zeros(3, 2)})
    with pytest.raises(ValueError, match="finite"):
        ctl.reset(good, {"joints": torch.full((2, 2), float("nan"))})
    with pytest.raises(ValueError, match="belief"):
        ctl.reset(good[:, :1], {"joints": torch.zeros(2, 2)})
    with pytest.raises(ValueError, match="action.drive"):
        controller(drive=("image",))
    with pytest.raises(ValueError, match="leak"):
        ActionConfig(leak=-1.0)
    with pytest.raises(ValueError, match="body"):
        VelocityController([ToyPlanarArm(), other_robot_joints()])
    with pytest.raises(RuntimeError, match="reset"):
        controller().act({"joints": torch.zeros(2, 2)}, DT)
    ctl.reset(good, {"joints": torch.zeros(2, 2)})
    with pytest.raises(ValueError, match="dt"):
        ctl.act({"joints": torch.from_numpy(good)}, 0.0)
    with pytest.raises(ValueError, match=r"observations\['joints'\]"):
        ctl.act({"joints": torch.zeros(3, 2)}, DT)


# ---- the goal attractor (aif/priors.py) ---------------------------------------------------------------------
BETA, PI_Z, K_Z = 3.0, 2.0, 0.5


def fd_jacobian(model, mu: torch.Tensor, h: float = 1e-6) -> torch.Tensor:
    """∂g/∂μ by central differences. (B, Dz) → (B, O, Dz)"""
    cols = []
    for i in range(mu.shape[1]):
        e = torch.zeros_like(mu)
        e[:, i] = h
        cols.append((model.predict(mu + e) - model.predict(mu - e)).reshape(len(mu), -1) / (2 * h))
    return torch.stack(cols, -1)


def attractor_case(seed: int = 11):
    arm = ToyPlanarArm()
    mu = planar_poses(5, seed=seed)
    goal = arm.predict(planar_poses(5, seed=seed + 1))                               # (B, 3) m
    formula = BETA * torch.einsum("bod,bo->bd", fd_jacobian(arm, mu), goal - arm.predict(mu))   # β Jᵀ (x_d − g)
    return arm, mu, goal, formula


def prior_only(order: int) -> Perception:
    """Perception whose F is the attractor alone (its sensor broken), one Euler step of Δt = 1e-7 s."""
    flow = FlowSettings(k_z=K_Z, integrator="euler", dt=1e-7, step_control="none", divergence_ratio=None)
    cfg = PerceptionConfig(order=order, prior="attractor", prior_precision=PI_Z, attractor_gain=BETA, flow=flow,
                           max_steps=1, max_step=None)
    return Perception([ToyPlanarArm()], cfg, precisions={"ee_xyz": 0.0})


@pytest.mark.parametrize("order", [0, 1, 2])
def test_attractor_drift_equals_its_formula(order):
    """The belief's drift under the attractor alone, measured by finite differences in time, is the documented f:
    k Π_z f at order 0 (−∂F_z/∂μ = Π_z f, β linear), and f itself at orders 1–2 once μ', μ'' sit at f and A f."""
    arm, mu, goal, f = attractor_case()
    pull = attractor(arm, mu, goal, BETA, torch.ones_like(goal))
    torch.testing.assert_close(pull.flow, f, rtol=1e-6, atol=1e-8)                  # f = β Jᵀ (x_d − g)
    u = torch.zeros(len(mu), order + 1, 2, dtype=torch.float64)
    u[:, 0] = mu
    if order >= 1:
        u[:, 1] = f
    if order == 2:
        u[:, 2] = torch.einsum("bde,be->bd", pull.jacobian, f)                        # μ'' = A μ'
    result = prior_only(order).infer({}, u, goal={"ee_xyz": goal})
    drift = (result.mu_tilde[:, 0] - mu) / 1e-7                                      # (B, 2) rad/s
    expected = K_Z * PI_Z * f if order == 0 else f
    torch.testing.assert_close(drift, expected, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("order", [0, 1, 2])
def test_attractor_gradient_matches_finite_differences_of_its_free_energy(order):
    """∂F_z/∂μ̃ against central differences of F_z: in μ at order 0 (F_z = Π_z V, exact), in μ' and μ'' above
    (the Gauss–Newton A is held fixed in μ there, so the μ block is compared at order 0 only)."""
    arm, mu, goal, _ = attractor_case(seed=21)
    g = torch.Generator().manual_seed(3)
    u = torch.randn(len(mu), order + 1, 2, generator=g, dtype=torch.float64)
    u[:, 0] = mu

    def free(v):
        pull = attractor(arm, v[:, 0], goal, BETA, torch.ones_like(goal))
        return prior_terms(v, "attractor", PI_Z, pull.flow, pull.jacobian, pull.potential)

    terms, h = free(u), 1e-6
    blocks = [0] if order == 0 else range(1, order + 1)
    for i in blocks:
        for d in range(2):
            e = torch.zeros_like(u)
            e[:, i, d] = h
            fd = (free(u + e).free_energy - free(u - e).free_energy) / (2 * h)
            torch.testing.assert_close(terms.grad[:, i, d], fd, rtol=1e-5, atol=1e-6)


def test_order_zero_attractor_is_linear_in_the_gain():
    """β enters once (the old penalty ½ Π_z |f|² made the pull grow with β²)."""
    arm, mu, goal, _ = attractor_case(seed=31)
    one, two = (prior_terms(mu[:, None], "attractor", PI_Z, p.flow, p.jacobian, p.potential)
                for p in (attractor(arm, mu, goal, b, torch.ones_like(goal)) for b in (BETA, 2 * BETA)))
    torch.testing.assert_close(two.grad, 2 * one.grad)
    torch.testing.assert_close(two.hessian, 2 * one.hessian)


def test_gauss_newton_geometry_moves_the_output_along_its_error_on_a_redundant_arm():
    """On the 7-DOF panda J f_GN ≈ β (x_d − g) (straight to the goal); Jᵀe's image J Jᵀ e is skewed."""
    from bodyschema.models.analytic import AnalyticModel
    arm = AnalyticModel("panda", "ee_xyz")
    g = np.random.default_rng(5)
    low, high = np.asarray(arm.body.q_low), np.asarray(arm.body.q_high)
    mu = torch.from_numpy(g.uniform(low + 0.3 * (high - low), high - 0.3 * (high - low), (20, 7)))
    goal = arm.predict(torch.from_numpy(g.uniform(low + 0.3 * (high - low), high - 0.3 * (high - low), (20, 7))))
    err = goal - arm.predict(mu)                                                     # (B, 3) m
    jac = arm.jacobian(mu)
    cos = {}
    for geometry in ("gradient", "gauss_newton"):
        f = attractor(arm, mu, goal, 2.0, torch.ones_like(goal), geometry).flow
        moved = torch.einsum("bod,bd->bo", jac, f)                                   # (B, 3) m/s
        cos[geometry] = torch.nn.functional.cosine_similarity(moved, err, dim=1)
    assert cos["gauss_newton"].min() > 0.98
    assert cos["gradient"].mean() < cos["gauss_newton"].mean() - 0.05


def test_image_goals_use_vjps_only():
    """An unseen image goal costs VJPs, never a Jacobian; an observed one is fused with the image's own term and
    costs no model call of its own (the same Jacobians as perceiving without the goal)."""
    image, joints = ToyBlobImage(), ToyJoints(precision=10.0)
    q = planar_poses(6, seed=41)
    goal = {"image": image.predict(perturb(q, seed=42, max_rad=0.1))}             # blobs overlap: a gradient
    cfg = PerceptionConfig(prior="attractor", attractor_gain=1e3, max_steps=30, method="flow")
    image.calls = {"vjp": 0, "jacobian": 0}
    moved = Perception([image, joints], cfg, precisions={"image": 0.0}).infer({"joints": q}, q, goal=goal)
    assert image.calls["jacobian"] == 0 and image.calls["vjp"] > 0, image.calls
    before = (image.predict(q) - goal["image"]).pow(2).mean(dim=(1, 2))
    after = (image.predict(moved.mu) - goal["image"]).pow(2).mean(dim=(1, 2))
    assert (after < 0.5 * before).all()                                               # pulled toward the goal
    seen = {"image": image.predict(q), "joints": q}
    calls, mus = [], []
    for with_goal in (False, True):
        image.calls = {"vjp": 0, "jacobian": 0}
        c = replace(cfg, prior="attractor" if with_goal else "none", max_steps=5, tol=0.0)
        mus.append(Perception([image, joints], c).infer(seen, q, goal=goal if with_goal else None).mu)
        calls.append(dict(image.calls))
    assert calls[0] == calls[1], calls
    assert (mus[1] - q).abs().max() > 1e-3 > (mus[0] - q).abs().max()                 # the fused goal pulls


def test_geometry_names_are_checked():
    from bodyschema.aif.aic_config import AICConfig
    with pytest.raises(ValueError, match="goal_geometry"):
        AICConfig(goal_geometry="newton")
    arm, mu, goal, _ = attractor_case(seed=51)
    with pytest.raises(ValueError, match="geometry"):
        attractor(arm, mu, goal, BETA, torch.ones_like(goal), "newton")
