"""Multi-start perception picks, per trial, a start of lowest free energy."""

from __future__ import annotations

import math

import pytest
import torch

from bodyschema.aif.multistart import infer_multistart, lowest_free_energy
from bodyschema.aif.perception import Perception, PerceptionConfig
from tests.aif.toys import ToyJoints, planar_poses
from tests.toy_models import ToyPlanarArm


def test_multistart_finds_the_pose_a_single_far_start_misses():
    arm, joints = ToyPlanarArm(), ToyJoints(precision=1.0)               # a weak joint sensor breaks elbow symmetry
    q = planar_poses(60, seed=0)
    obs = {"ee_xyz": arm.predict(q), "joints": q}
    perception = Perception([arm, joints])
    far = planar_poses(60, seed=1).flip(0)                                 # another target's pose (level 3)
    far[:, 1] = -far[:, 1]                                                 # the other elbow branch
    single = perception.infer(obs, far)
    g = torch.Generator().manual_seed(2)
    starts = torch.cat([far[:, None], (torch.rand(60, 7, 2, generator=g, dtype=torch.float64) * 2 - 1) * 2.5], 1)
    multi = infer_multistart(perception, obs, starts, screen_steps=20, keep=2)
    assert (multi.result.F <= single.F + 1e-9).all()
    ok_single = ((single.mu - q).abs().amax(-1) < math.radians(1)).float().mean()
    ok_multi = ((multi.result.mu - q).abs().amax(-1) < math.radians(1)).float().mean()
    assert ok_multi > ok_single and ok_multi > 0.9, (ok_single, ok_multi)
    assert multi.chosen.shape == (60,) and multi.screen_F.shape == (60, 8)


def test_bad_starts_raise():
    perception = Perception([ToyPlanarArm()])
    with pytest.raises(ValueError, match="starts must be"):
        infer_multistart(perception, {"ee_xyz": torch.zeros(2, 3, dtype=torch.float64)}, torch.zeros(2, 2))
    with pytest.raises(ValueError, match="keep must be"):
        infer_multistart(perception, {"ee_xyz": torch.zeros(2, 3, dtype=torch.float64)}, torch.zeros(2, 3, 2), keep=4)


def test_lowest_free_energy_picks_per_trial_the_start_of_lower_F_and_counts_both_starts_work():
    arm = ToyPlanarArm()
    q = planar_poses(40, seed=0)
    obs = {"ee_xyz": arm.predict(q)}
    perception = Perception([arm], PerceptionConfig(record=True))
    near, far = perception.infer(obs, q + 0.05), perception.infer(obs, planar_poses(40, seed=1))
    picked, chosen = lowest_free_energy([near, far])
    assert torch.equal(picked.F, torch.minimum(near.F, far.F))
    for name in ("mu", "steps", "converged"):
        assert torch.equal(getattr(picked, name), torch.where(
            (chosen == 0).reshape(-1, *[1] * (getattr(near, name).ndim - 1)), getattr(near, name),
            getattr(far, name))), name
    assert picked.evaluations == near.evaluations + far.evaluations
    steps = max(len(near.trajectory["F"]), len(far.trajectory["F"]))
    assert picked.trajectory["F"].shape == (steps, 40) and picked.trajectory["mu"].shape[:2] == (steps, 40)
    i = int(chosen.nonzero()[0]) if chosen.any() else 0
    own = (near, far)[int(chosen[i])].trajectory["F"][:, i]
    assert torch.equal(picked.trajectory["F"][:len(own), i].nan_to_num(-1), own.nan_to_num(-1))
    assert picked.trajectory["F"][len(own):, i].isnan().all()
