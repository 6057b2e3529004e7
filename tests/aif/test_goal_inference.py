"""Goal inference: the imagined pose produces the goal, the nearest exact solution wins, the joint goal's
precision outweighs the senses by its gain, bad input raises the house error."""

from __future__ import annotations

import pytest
import torch

from bodyschema.aif.goal_inference import goal_precision, infer_goal_pose
from bodyschema.aif.perception import Perception, PerceptionConfig
from tests.aif.toys import ToyBlobImage, ToyJoints, planar_poses
from tests.toy_models import LINKS_M, ToyPlanarArm


def test_the_imagined_pose_produces_the_goal_from_a_far_belief():
    """From the other elbow branch the belief alone stalls at a joint limit for some goals; random starts find
    them, and the chosen pose is never worse than the belief's own."""
    arm = ToyPlanarArm()
    perception = Perception([arm])
    q = planar_poses(40, seed=0)
    goal = {"ee_xyz": arm.predict(q)}
    far = planar_poses(40, seed=1).flip(0)
    far[:, 1] = -far[:, 1]                                                 # the other elbow branch
    g = torch.Generator().manual_seed(2)
    guesses = (torch.rand(40, 15, 2, generator=g, dtype=torch.float64) * 2 - 1) * 2.5
    alone = infer_goal_pose(perception, goal, far)
    pose = infer_goal_pose(perception, goal, far, guesses)
    exact = lambda p: ((arm.predict(p.q) - goal["ee_xyz"]).norm(dim=-1) < 1e-4).double().mean()   # noqa: E731 — a metric
    assert exact(pose) >= 0.95 and exact(pose) > exact(alone), (exact(alone), exact(pose))
    assert (pose.F <= alone.F + 1.0).all()                                  # within the margin of the belief's
    assert pose.q.shape == (40, 2) and pose.chosen.shape == (40,) and (alone.chosen == 0).all()


def test_an_image_goal_is_imagined_through_the_image_models_own_update():
    """An image goal (a large output: adam+lm, as perception's levels take) is reproduced by the imagined pose."""
    image = ToyBlobImage()
    q = planar_poses(12, seed=5)
    goal = {"image": image.predict(q)}
    g = torch.Generator().manual_seed(6)
    guesses = (torch.rand(12, 4, 2, generator=g, dtype=torch.float64) * 2 - 1) * 2.5
    start = planar_poses(12, seed=7)
    pose = infer_goal_pose(Perception([image], PerceptionConfig(method="adam+lm")), goal, start, guesses)
    ee_err = (image.arm.predict(pose.q) - image.arm.predict(q)).norm(dim=-1)   # (12,) m: the blob fixes the ee only
    assert (ee_err < 1e-3).double().mean() >= 0.9, ee_err


def test_of_two_exact_solutions_the_one_nearest_the_belief_wins():
    """A planar arm reaches an ee position elbow-up or elbow-down: the same F, and the imagination keeps the
    solution the arm is nearest to, whichever start found it."""
    arm = ToyPlanarArm()
    perception = Perception([arm])
    l1, l2 = LINKS_M
    q = planar_poses(30, seed=3)
    a, b = q.unbind(-1)
    mirror = torch.stack([a + 2 * torch.atan2(l2 * b.sin(), l1 + l2 * b.cos()), -b], -1)   # the elbow's other branch
    inside = mirror[:, 0].abs() < 2.3                                      # both branches within the joint limits
    q, mirror = q[inside], mirror[inside]
    goal = {"ee_xyz": arm.predict(q)}
    assert len(q) >= 10 and (arm.predict(mirror) - goal["ee_xyz"]).norm(dim=-1).max() < 1e-12
    for near, other in ((q, mirror), (mirror, q)):
        pose = infer_goal_pose(perception, goal, near + 0.05, (other + 0.05)[:, None])
        assert (pose.q - near).abs().max() < 1e-3                           # the branches are > 0.5 rad apart
        assert (pose.chosen == 0).all()
        pose = infer_goal_pose(perception, goal, other + 0.3, (near + 0.01)[:, None])
        assert (pose.q - other).abs().max() < 1e-3                        # nearest to the belief, not to the start


def test_the_joint_goal_outweighs_the_senses_by_its_gain():
    arm, joints = ToyPlanarArm(precision=1e4), ToyJoints(precision=1e3)
    mu = planar_poses(7, seed=4)
    assert goal_precision([joints], mu, 10.0) == pytest.approx(1e4)
    jac = arm.jacobian(mu)                                                 # (7, 3, 2)
    information = 1e4 * jac.pow(2).sum(1).mean(-1) + 1e3                   # (7,) mean diag of Σ JᵀΠJ
    assert goal_precision([arm, joints], mu, 10.0) == pytest.approx(10 * float(information.median()))
    assert goal_precision([arm, joints], mu, 10.0, {"ee_xyz": 0.0}) == pytest.approx(1e4)   # a broken sense
    assert goal_precision([arm, joints], mu, 10.0, {"ee_xyz": 1.0}) < goal_precision([arm, joints], mu, 10.0)


def test_bad_input_raises():
    perception = Perception([ToyPlanarArm()])
    goal = {"ee_xyz": torch.zeros(2, 3, dtype=torch.float64)}
    with pytest.raises(ValueError, match="belief must be"):
        infer_goal_pose(perception, goal, torch.zeros(2, 3, dtype=torch.float64))
    with pytest.raises(ValueError, match="guesses must be"):
        infer_goal_pose(perception, goal, torch.zeros(2, 2, dtype=torch.float64), torch.zeros(3, 1, 2))
    with pytest.raises(ValueError, match="margin must be"):
        infer_goal_pose(perception, goal, torch.zeros(2, 2, dtype=torch.float64), margin=-1.0)
