"""bodyschema.envs: Gymnasium's own env checker on every shipped robot and a robot from a file, seeded resets, the PD
baseline and the AIF controller as policies, registered ids, and bad input as the house error."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import bodyschema.envs
from bodyschema.datagen.body.record import SHIPPED
from bodyschema.envs import PDPolicy, RandomPolicy, ReachEnv, compare
from bodyschema.envs.registration import GENERIC_ID, env_id
from bodyschema.evaluation.reaching import AIFPolicy
from tests.evaluation.test_file_robot import write_arm


@pytest.fixture(scope="module")
def arm_file(tmp_path_factory) -> str:
    return str(write_arm(tmp_path_factory.mktemp("arm")))


def checked(env) -> None:
    """gymnasium's check_env on env (made by gymnasium.make, so its render modes are checked too), failing on any
    warning (the normalized-action advice included: actions are float32 in [-1, 1], test_action_space.py)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert not caught, [str(w.message) for w in caught]


@pytest.mark.parametrize("robot", SHIPPED)
def test_env_checker_passes_on_every_shipped_robot(robot):
    env = gymnasium.make(env_id(robot))
    checked(env)
    assert env.unwrapped.action_kind == env.unwrapped.robot.actuation


@pytest.mark.parametrize("kwargs", [{"robot": "nao_arm", "image": True, "goal": "image"},
                                    {"robot": "nao_arm", "goal": "ee_pixel", "action": "velocity"},
                                    {"robot": "panda", "goal": "joints", "action": "velocity"}],
                         ids=["image-goal", "servo-velocity", "torque-velocity"])
def test_env_checker_passes_with_images_goals_and_velocity_actions(kwargs):
    checked(gymnasium.make(GENERIC_ID, **kwargs))


def test_env_checker_passes_on_a_robot_from_a_file(arm_file):
    env = gymnasium.make(GENERIC_ID, robot=arm_file, image=True)
    checked(env)
    assert env.unwrapped.robot.name == "arm3" and env.observation_space["image"].shape == (16, 16)


def test_every_shipped_robot_is_registered():
    for robot in SHIPPED:
        assert gymnasium.make(env_id(robot)).unwrapped.robot.name == robot
    bodyschema.envs.registration.register_envs()            # a second registration is silent and changes nothing
    assert gymnasium.spec(env_id("panda")).kwargs == {"robot": "panda"}


def test_a_seeded_reset_reproduces_the_goal_and_the_start():
    first, second = ReachEnv("panda"), ReachEnv("panda")
    a, _ = first.reset(seed=7)
    b, _ = second.reset(seed=7)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=f"observation {key!r} differs under one seed")
    np.testing.assert_array_equal(first.goal_pose, second.goal_pose)
    c, _ = second.reset(seed=8)
    assert not np.array_equal(a["goal"], c["goal"]) and not np.array_equal(a["joints"], c["joints"])
    # the goal is what the sensor reads at the goal pose, a pose inside the sampling ranges
    np.testing.assert_allclose(a["goal"], first.robot.fk(first.goal_pose)[0])
    low, high = first.robot.sampling_ranges.T
    assert ((first.goal_pose >= low) & (first.goal_pose <= high)).all()


def test_observations_are_the_simulated_arm_and_the_reward_its_ee_error():
    env = ReachEnv("nao_arm", goal="ee_pixel", image=True, render_mode="rgb_array")
    obs, info = env.reset(seed=3)
    obs, reward, _, _, info = env.step(env.action_space.sample())
    q = env.arm.q
    np.testing.assert_allclose(obs["joints"], q[0])
    np.testing.assert_allclose(obs["ee_xyz"], env.robot.fk(q, check=False)[0], atol=1e-12)
    np.testing.assert_array_equal(obs["image"], env.robot.render(q, check=False)[0])
    np.testing.assert_allclose(obs["goal"], env.robot.project(env.goal_xyz)[0])
    assert reward == pytest.approx(-np.linalg.norm(obs["ee_xyz"] - env.goal_xyz[0]))
    assert info["ee_error_mm"] == pytest.approx(-1e3 * reward)
    frame = env.render()
    assert frame.shape == (*env.robot.image_size, 3) and frame.dtype == np.uint8
    np.testing.assert_array_equal(frame[..., 0], obs["image"])


def easy_episode(env, offset_rad: float = 0.15):
    """A goal pose and a start every joint `offset_rad` from it, inside the sampling ranges."""
    low, high = env.robot.sampling_ranges.T
    target = 0.5 * (low + high)
    return {"target": target, "start": np.clip(target + offset_rad, low, high)}


def run_episode(env, policy, options) -> tuple[float, dict, int]:
    """→ the first ee error (mm), the last info, steps."""
    obs, info = env.reset(seed=0, options=options)
    first, done, steps = info["ee_error_mm"], False, 0
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        done, steps = terminated or truncated, steps + 1
    return first, info, steps


@pytest.mark.parametrize("robot", ["nao_arm", "panda"])
def test_the_pd_baseline_reaches_an_easy_goal_and_the_episode_ends_there(robot):
    env = ReachEnv(robot)
    _, info, steps = run_episode(env, PDPolicy(env), easy_episode(env))
    assert info["success"] and info["ee_error_mm"] < env.success_mm and "failure" not in info
    assert steps < env.max_steps                              # terminated within success_mm and resting
    assert env.ee_speed() < 0.01


@pytest.mark.parametrize("action", ["position", "velocity"])
def test_the_aif_policy_reduces_the_error(action):
    env = ReachEnv("nao_arm", action=action, duration=1.5)
    policy = AIFPolicy(env)
    first, info, _ = run_episode(env, policy, easy_episode(env, 0.3))
    assert info["ee_error_mm"] < 0.1 * first, (first, info)
    assert policy.imagined_pose is not None                   # goal inference ran on the ee_xyz goal ("auto")


def test_compare_gives_every_policy_the_same_episodes():
    env = gymnasium.make(env_id("planar2"), duration=0.2)
    goals = {"a": [], "b": []}

    def recorder(name):
        random = RandomPolicy(env, seed=1)

        def policy(obs):
            if not goals[name] or not np.array_equal(goals[name][-1], obs["goal"]):
                goals[name].append(obs["goal"].copy())
            return random(obs)
        return policy

    scores = compare(env, {"a": recorder("a"), "b": recorder("b")}, episodes=3, seed=5)
    assert len(goals["a"]) == 3 and all(np.array_equal(x, y) for x, y in zip(goals["a"], goals["b"]))
    assert scores["a"] == scores["b"] and scores["a"].episodes == 3 and 0 <= scores["a"].success_rate <= 1


def test_bad_input_is_the_house_error(arm_file):
    cases = [({"robot": "nope"}, "robot must be"), ({"goal": "touch"}, "goal must be one of"),
             ({"action": "torque"}, "action must be 'auto', 'velocity' or 'position'"),
             ({"robot": "panda", "action": "position"}, "action must be 'auto', 'velocity' or 'torque'"),
             ({"success_mm": -1.0}, "success_mm must be a finite number > 0 (mm)"),
             ({"duration": float("nan")}, "duration must be"), ({"image": "yes"}, "image must be True or False"),
             ({"render_mode": "human"}, "render_mode must be None or 'rgb_array'"),
             ({"image_size": (2, 2)}, "image_size must be")]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
            ReachEnv(**kwargs)
    env = ReachEnv("planar2")
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be a finite array of shape \(2,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="reset options must be keys among"):
        env.reset(options={"goal": 1})
    with pytest.raises(ValueError, match="q must be an array of shape"):
        env.reset(options={"target": [0.0, 0.0, 0.0]})
    with pytest.raises(ValueError, match="the env's action must be 'position' or 'torque' for PDPolicy"):
        PDPolicy(ReachEnv("planar2", action="velocity"))
    with pytest.raises(ValueError, match="model body must be"):
        AIFPolicy(env, models=[f"analytic:{arm_file}:ee_xyz"])
    with pytest.raises(ValueError, match="models must be a non-empty list"):
        AIFPolicy(env, models="analytic:planar2:ee_xyz")


def test_without_gymnasium_the_import_names_the_extra():
    code = "import sys; sys.modules['gymnasium'] = None; import bodyschema.envs"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "gymnasium must be installed for bodyschema.envs" in done.stderr and "bodyschema[envs]" in done.stderr
