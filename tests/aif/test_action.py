"""Action by free-energy descent: the law, the velocity controller's closed loop on a kinematic arm, failures."""

import numpy as np
import pytest
import torch

from bodyschema.aif.action import ActionConfig, VelocityController, action_rate
from bodyschema.aif.perception import PerceptionConfig
from tests.aif.toys import ToyJoints, other_robot_joints, planar_poses
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
