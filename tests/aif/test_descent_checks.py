"""Adam and LM reading whether a trial stopped every `check_every` steps (aif/descent.py): a stopped trial stays
masked, so every K gives the rows of compacting every step: the same steps, the same convergence, the same beliefs
(exactly for a model whose rows do not depend on the batch; a float32 network may round the larger batch differently,
which the descent can amplify: measured up to 9.7e-3 rad on a 16×16 decoder, so K > 1 is opt-in)."""

from __future__ import annotations

import pytest
import torch

from bodyschema.aif import descent
from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.aif.perception_config import LMSettings
from tests.aif.toys import ToyBlobImage, perturb, planar_poses
from tests.toy_models import ToyPlanarArm


def _infer(model, method: str, k: int, n: int = 40, trial_derivatives: bool = False):
    q = planar_poses(n, seed=3)
    obs = {model.modality: model.predict(q)}
    config = PerceptionConfig(method=method, record=False, check_every=k,
                              lm=LMSettings(trial_derivatives=trial_derivatives))
    return Perception([model], config).infer(obs, perturb(q, seed=4, max_rad=0.4))


@pytest.mark.parametrize("method", ["adam", "lm", "adam+lm"])
@pytest.mark.parametrize("make", [ToyPlanarArm, ToyBlobImage], ids=["kinematics", "blob-image"])
@pytest.mark.parametrize("k", [2, 4, 7])
def test_compacting_every_k_steps_gives_the_rows_of_every_step(make, method, k):
    one, every_k = _infer(make(), method, 1), _infer(make(), method, k)
    assert torch.equal(one.steps, every_k.steps)
    assert torch.equal(one.converged, every_k.converged)
    assert torch.equal(one.mu, every_k.mu)
    assert torch.equal(one.F, every_k.F)
    assert one.steps.min() < one.steps.max()                              # trials stopped at different steps


@pytest.mark.parametrize("make", [ToyPlanarArm, ToyBlobImage], ids=["kinematics", "blob-image"])
def test_lm_taking_the_derivatives_with_each_trial_gives_the_same_rows(make):
    """What check_every > 1 switches on (derivatives with the trial, accepted rows taken by a mask) is the same
    arithmetic as asking them where a step was accepted."""
    asked, with_trial = _infer(make(), "lm", 1), _infer(make(), "lm", 1, trial_derivatives=True)
    assert torch.equal(asked.mu, with_trial.mu) and torch.equal(asked.steps, with_trial.steps)
    assert torch.equal(asked.converged, with_trial.converged) and torch.equal(asked.F, with_trial.F)


def test_trials_stop_at_different_steps_and_the_stopped_ones_are_still_evaluated_until_a_compaction():
    """The evaluations count the masked trials carried to the next compaction: more than compacting every step,
    at most K − 1 more per trial."""
    model, k = ToyPlanarArm(), 4
    one, every_k = _infer(model, "adam", 1), _infer(model, "adam", k)
    assert one.evaluations <= every_k.evaluations <= one.evaluations + (k - 1) * len(one.steps)


def test_recording_compacts_every_step_so_the_trajectory_is_unchanged():
    model = ToyPlanarArm()
    q = planar_poses(6, seed=3)
    obs = {"ee_xyz": model.predict(q)}
    runs = [Perception([model], PerceptionConfig(method="adam", record=True, check_every=k))
            .infer(obs, perturb(q, seed=4)) for k in (1, 5)]
    for name in runs[0].trajectory:
        assert torch.equal(runs[0].trajectory[name].nan_to_num(-9), runs[1].trajectory[name].nan_to_num(-9)), name


def test_check_every_must_be_positive():
    with pytest.raises(ValueError, match="check_every"):
        PerceptionConfig(check_every=0)


def test_the_default_checks_every_step():
    assert PerceptionConfig().check_every == 1                           # exact on CPU: opt in where a sync costs
    for function in (descent.adam, descent.levenberg_marquardt):        # the functions themselves: every step
        assert function.__kwdefaults__["check_every"] == 1
