"""One reach and one seed helper for every benchmark (issue 22, item 5).

Reaching checks an ee_xyz goal against `datagen.reach.arm_reach`, the bound datagen's validation uses: no pose of
the arm lies beyond it, and a goal just beyond it is refused. Its seed streams are `core.seeds.eval_rng` with the
REACHING stream: the same words as before the merge, so published reaching results keep their targets.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bodyschema.datagen.body.reach import arm_reach
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.samplers import uniform
from bodyschema.evaluation.core.seeds import EVAL_STREAM, PURPOSE, REACHING, eval_rng
from bodyschema.evaluation.reaching.goals import check_goal


@pytest.fixture(scope="module", params=["nao_arm", "planar2", "panda"])
def robot(request):
    with Robot.load(request.param) as arm:
        yield arm


def test_no_pose_of_the_arm_is_beyond_the_reach_goals_are_checked_against(robot):
    base, reach = arm_reach(robot.model, robot.ee_site)
    q = uniform(np.random.default_rng(0), robot.joint_limits, 2000)                 # (2000, Dq) rad
    distance = np.linalg.norm(robot.fk(q) - base, axis=1)                          # (2000,) m
    assert distance.max() <= reach * (1 + 1e-9)
    check_goal(robot, "ee_xyz", torch.from_numpy(robot.fk(q)), (3,))              # every real pose passes


def test_a_goal_just_beyond_the_reach_is_refused(robot):
    base, reach = arm_reach(robot.model, robot.ee_site)
    direction = np.array([0.6, 0.0, 0.8])
    goal = torch.from_numpy(base + 1.001 * reach * direction)[None]               # (1, 3) m
    with pytest.raises(ValueError, match="ee_xyz goal must be within the arm's reach"):
        check_goal(robot, "ee_xyz", goal, (3,))


def test_reaching_draws_keep_their_seed_words():
    for purpose, code in REACHING.purposes.items():
        words = [EVAL_STREAM, REACHING.word, 7, code]
        expected = np.random.default_rng(np.random.SeedSequence(words)).random(5)
        np.testing.assert_array_equal(eval_rng(7, None, purpose, stream=REACHING).random(5), expected,
                                      err_msg=f"reaching's {purpose!r} stream moved")


def test_the_default_stream_keeps_its_words_and_differs_from_reaching():
    for purpose, code in PURPOSE.items():
        words = [EVAL_STREAM, 7, 2, code, 5]
        expected = np.random.default_rng(np.random.SeedSequence(words)).random(5)
        np.testing.assert_array_equal(eval_rng(7, 2, purpose, 5).random(5), expected)
    levels, reaching = eval_rng(7, 0, "targets").random(5), eval_rng(7, None, "targets", stream=REACHING).random(5)
    assert not np.allclose(levels, reaching)
