"""The agent's action space: float32 in [-1, 1] per actuator, mapped affinely onto the native box (servo targets rad,
torques N·m, velocity commands rad/s: `native_action_space`, float64), -1 → low, +1 → high; the map round-trips, the
env steps with the native command the action stands for, and Stable-Baselines3's checker (where installed; it is not a
dependency) passes without a warning, as gymnasium's does (test_reach_env.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from bodyschema.envs import ReachEnv  # noqa: E402

KINDS = [("planar2", "auto"), ("nao_arm", "velocity"), ("panda", "auto"), ("panda", "velocity")]


@pytest.fixture(scope="module", params=KINDS, ids=[f"{r}-{a}" for r, a in KINDS])
def env(request):
    robot, action = request.param
    env = ReachEnv(robot, action=action)
    yield env
    env.close()


def test_actions_are_float32_in_a_symmetric_unit_box(env):
    space, native = env.action_space, env.native_action_space
    assert space.dtype == np.float32 and space.shape == native.shape == (env.robot.model.nu,)
    assert (space.low == -1).all() and (space.high == 1).all()
    assert native.dtype == np.float64 and (native.low < native.high).all()
    if env.action_kind == "position":
        np.testing.assert_array_equal(np.stack([native.low, native.high], 1), env.robot.model.actuator_ctrlrange)


def test_the_map_round_trips_to_the_native_box(env):
    native = env.native_action_space
    rng = np.random.default_rng(0)
    a = rng.uniform(-1, 1, size=(200, *native.shape)).astype(np.float32)
    commands = np.stack([env.to_native(x) for x in a])                                 # (200, nu) native
    assert ((commands >= native.low) & (commands <= native.high)).all()
    np.testing.assert_allclose(np.stack([env.to_action(c) for c in commands]), a, atol=1e-6)
    x = rng.uniform(native.low, native.high, size=(200, *native.shape))
    back = np.stack([env.to_native(env.to_action(c)) for c in x])
    np.testing.assert_allclose(back, x, atol=1e-6 * (native.high - native.low).max())   # float32 of the range
    np.testing.assert_array_equal(env.to_native(-np.ones(native.shape)), native.low)
    np.testing.assert_array_equal(env.to_native(np.ones(native.shape)), native.high)
    np.testing.assert_allclose(env.to_native(np.zeros(native.shape)), (native.low + native.high) / 2)
    np.testing.assert_array_equal(env.to_native(np.full(native.shape, 5.0)), native.high)    # clipped to the box
    assert env.to_action(native.high + 10).tolist() == [1.0] * native.shape[0]


def test_a_step_applies_the_native_command_the_action_stands_for(env):
    env.reset(seed=0)
    a = env.action_space.sample()
    given = []
    ctrl = env._ctrl
    env._ctrl = lambda action: given.append(env.to_native(action)) or ctrl(action)
    try:
        env.step(a)
    finally:
        del env._ctrl
    np.testing.assert_array_equal(given[0], env.native_action_space.low + (a.astype(np.float64) + 1) / 2
                                  * (env.native_action_space.high - env.native_action_space.low))


@pytest.mark.parametrize("robot", ["planar2", "panda"])
def test_stable_baselines3_checker_passes_without_warnings(robot):
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = ReachEnv(robot)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env_checker.check_env(env, warn=True)
    env.close()
    assert not caught, [str(w.message) for w in caught]
