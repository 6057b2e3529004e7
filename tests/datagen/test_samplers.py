"""Samplers: kinematic poses stay in range with the stated statistics; babbling tracks targets, at rest first, and
records the targets it tracks."""

import numpy as np
import pytest

from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.samplers import Babbler, gaussian, sample_kinematic, to_stored_q, uniform

RANGES = np.array([[-1.0, 2.0], [0.5, 0.7], [-3.0, -2.0]])


def test_uniform_covers_the_box_evenly():
    q = uniform(np.random.default_rng(0), RANGES, 20_000)
    assert q.shape == (20_000, 3)
    assert (q >= RANGES[:, 0]).all() and (q <= RANGES[:, 1]).all()
    np.testing.assert_allclose(q.mean(0), RANGES.mean(1), atol=0.02 * np.ptp(RANGES, 1).max())
    np.testing.assert_allclose(q.std(0), np.ptp(RANGES, 1) / np.sqrt(12), rtol=0.03)  # uniform variance


def test_gaussian_is_centred_with_range_over_six_and_clipped():
    q = gaussian(np.random.default_rng(1), RANGES, 50_000)
    assert (q >= RANGES[:, 0]).all() and (q <= RANGES[:, 1]).all()
    assert (np.abs(q.mean(0) - RANGES.mean(1)) < 0.01 * np.ptp(RANGES, 1)).all()
    np.testing.assert_allclose(q.std(0), np.ptp(RANGES, 1) / 6, rtol=0.03)  # clipping at 3 sigma barely matters
    at_bounds = (q == RANGES[:, 0]) | (q == RANGES[:, 1])
    assert 0 < at_bounds.mean() < 0.01  # ~0.27 % beyond 3 sigma end up exactly on the bounds


def test_kinematic_samples_are_seeded_float32_inside_limits():
    limits = RANGES + [[-0.1, 0.1]]
    a = sample_kinematic("uniform", np.random.default_rng(5), RANGES, limits, 100)
    b = sample_kinematic("uniform", np.random.default_rng(5), RANGES, limits, 100)
    c = sample_kinematic("uniform", np.random.default_rng(6), RANGES, limits, 100)
    assert a.dtype == np.float32 and np.array_equal(a, b) and not np.array_equal(a, c)
    with pytest.raises(ValueError, match="sampler must be one of"):
        sample_kinematic("sobol", np.random.default_rng(0), RANGES, limits, 3)


def test_stored_q_is_clipped_to_the_joint_limits():
    limits = np.array([[-1.0, 1.0]])
    q = to_stored_q(np.array([[-1.2], [0.3], [1.0000001]]), limits)
    assert q.dtype == np.float32 and q.min() >= -1 and q.max() <= 1 and q[1, 0] == np.float32(0.3)


@pytest.fixture(scope="module")
def planar2():
    robot = Robot.load("planar2")
    yield robot
    robot.close()


def test_babbling_episode_starts_at_rest_records_at_the_rate_and_moves(planar2):
    babbler = Babbler(planar2.model, list(planar2.joint_names), planar2.joint_limits, 20.0, (0.2, 0.6))
    ep = babbler.episode(np.random.default_rng(0), planar2.sampling_ranges, 200)
    q, qvel, t = ep["q"], ep["qvel"], ep["t"]
    assert q.shape == qvel.shape == (200, 2) and t.shape == (200,)
    assert q.dtype == qvel.dtype == t.dtype == np.float32
    assert t[0] == 0 and np.all(qvel[0] == 0)  # at rest at the start
    np.testing.assert_allclose(np.diff(t), 1 / babbler.rate_hz, rtol=1e-4)
    assert abs(babbler.rate_hz - 20.0) < 0.5
    lo, hi = planar2.joint_limits[:, 0], planar2.joint_limits[:, 1]
    assert (q >= lo.astype(np.float32)).all() and (q <= hi.astype(np.float32)).all()
    assert (np.ptp(q, axis=0) > 1.0).all()  # the servos really chase the random targets
    # the recorded velocity is the derivative of the recorded trajectory (central differences, 50 ms apart)
    fd = (q[2:] - q[:-2]) / (t[2:] - t[:-2])[:, None]
    for j in range(2):
        assert np.corrcoef(fd[:, j], qvel[1:-1, j])[0, 1] > 0.9


def held_targets(target: np.ndarray, episode: np.ndarray) -> list[tuple[int, int]]:
    """[(from, to)] row ranges over which one target is held within one episode."""
    change = np.r_[True, (target[1:] != target[:-1]).any(axis=1) | (episode[1:] != episode[:-1])]
    starts = np.flatnonzero(change)
    return list(zip(starts.tolist(), [*starts[1:].tolist(), len(target)]))


def test_babbling_records_the_targets_the_servos_converge_to(planar2):
    babbler = Babbler(planar2.model, list(planar2.joint_names), planar2.joint_limits, 20.0, (0.2, 1.0))
    ranges = planar2.sampling_ranges
    ep = babbler.episodes(np.random.default_rng(0), ranges, [100, 100], first_episode=0)
    q, target = ep["q"].astype(np.float64), ep["target"]
    assert target.shape == q.shape == (200, 2) and target.dtype == np.float32
    assert (target >= ranges[:, 0] - 1e-6).all() and (target <= ranges[:, 1] + 1e-6).all()   # drawn in the box
    holds = [(a, b) for a, b in held_targets(target, ep["episode"]) if b - a >= 2]
    assert len(holds) >= 10                      # 10 s of 0.2-1 s holds
    for a, b in holds:                           # a servo closes the gap to the target it holds
        gap = np.linalg.norm(q[a:b] - target[a:b], axis=1)                                   # (b - a,) rad
        assert gap[-1] < gap[0], (a, b, gap)
        if b - a >= 0.5 * babbler.rate_hz:      # held >= 0.5 s: at least half the way there
            assert gap[-1] < 0.5 * gap[0], (a, b, gap)


def test_babbling_is_deterministic_given_the_generator_and_numbers_episodes(planar2):
    babbler = Babbler(planar2.model, list(planar2.joint_names), planar2.joint_limits, 25.0, (0.1, 0.3))
    a = babbler.episodes(np.random.default_rng(3), planar2.sampling_ranges, [50, 50, 20], first_episode=7)
    b = babbler.episodes(np.random.default_rng(3), planar2.sampling_ranges, [50, 50, 20], first_episode=7)
    for key in a:
        assert np.array_equal(a[key], b[key]), key
    assert a["episode"].dtype == np.int32 and np.array_equal(np.unique(a["episode"]), [7, 8, 9])
    assert np.array_equal(np.flatnonzero(a["t"] == 0), [0, 50, 100])  # each episode restarts its clock


def test_babbling_needs_position_servos():
    robot = Robot.load("planar2", actuators="torque")
    with pytest.raises(ValueError, match="actuators='position'"):
        Babbler(robot.model, list(robot.joint_names), robot.joint_limits, 20.0, (0.2, 0.5))


def test_babbling_records_the_simulated_touch_when_the_robot_has_a_sensor():
    robot = Robot.load("panda")
    babbler = Babbler(robot.model, list(robot.joint_names), robot.joint_limits, 20.0, (0.2, 0.5))
    assert babbler.touch_adr is not None
    ep = babbler.episode(np.random.default_rng(0), robot.sampling_ranges, 40)
    assert ep["touch"].shape == (40, 1) and ep["touch"].dtype == np.float32 and (ep["touch"] >= 0).all()
    planar = Robot.load("planar2")
    assert "touch" not in Babbler(planar.model, list(planar.joint_names), planar.joint_limits, 20.0,
                                  (0.2, 0.5)).episode(np.random.default_rng(0), planar.sampling_ranges, 5)
