"""The one precision rule of perception (aif/precisions.py): a model whose precision varies with the pose is perceived
at its sensor's precision, a precision the user names wins, any other model keeps its own; and the levels, reaching
and tracking benchmarks resolve the same precision for the same model."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import pytest
import torch

from bodyschema.aif.goal_inference import goal_precision
from bodyschema.aif.perception import Perception
from bodyschema.aif.precisions import perceived_precisions
from bodyschema.aif.tracker import Tracker
from bodyschema.aif.tracker_config import TrackerConfig
from bodyschema.base import modalities
from bodyschema.evaluation.levels.benchmark import LevelsConfig
from bodyschema.evaluation.reaching.benchmark import ReachingConfig, aif_policy
from bodyschema.evaluation.tracking.benchmark import TrackingConfig, sensed
from bodyschema.evaluation.tracking.methods import Clock
from tests.aif.toys import ToyBlobImage, ToyJoints, planar_poses
from tests.toy_models import ToyPlanarArm

EE_SENSOR = modalities.get("ee_xyz").precision            # 1e6 m⁻² (σ = 1 mm)


class ToyVaryingArm(ToyPlanarArm):
    """The planar arm with a GP-like precision: ~1e9 m⁻², 10× lower away from the elbow's middle."""

    kind = "toy_varying"
    precision_varies = True

    def _precision(self, z):
        return (1e9 / (1.0 + 9.0 * (z[:, 1:2] - 0.7) ** 2)).expand(z.shape[0], 3).clone()


class ToyVaryingImage(ToyBlobImage):
    precision_varies = True                               # an image has no sensor precision: it keeps its own


def test_a_pose_varying_model_is_perceived_at_its_sensors_precision():
    model = ToyVaryingArm()
    assert model.sensor_precision == EE_SENSOR
    assert perceived_precisions([model]) == {"ee_xyz": EE_SENSOR}
    assert Perception([model]).precisions == {"ee_xyz": EE_SENSOR}


@pytest.mark.parametrize("where", ["argument", "config"])
def test_a_precision_the_user_names_wins(where):
    model = ToyVaryingArm()
    if where == "argument":
        perception = Perception([model], precisions={"ee_xyz": 4.0})
    else:
        perception = Perception([model], replace(LevelsConfig().perception, precisions=(("ee_xyz", 4.0),)))
    assert perception.precisions == {"ee_xyz": 4.0}
    assert Perception([model], precisions={"ee_xyz": 0.0}).precisions == {"ee_xyz": 0.0}    # a broken sensor


def test_a_model_with_a_fixed_or_calibrated_precision_keeps_its_own():
    assert Perception([ToyPlanarArm(precision=3e4)]).precisions == {}
    assert Perception([ToyVaryingArm(), ToyJoints(precision=50.0)]).precisions == {"ee_xyz": EE_SENSOR}
    assert perceived_precisions([ToyVaryingImage()]) == {}


def test_a_pose_varying_model_perceived_by_the_rule_lands_on_the_reading():
    """At the sensor's constant Π the belief ends on the reading (within 10 µm: tol 1e-5 rad stops the flow)."""
    model, q = ToyVaryingArm(), planar_poses(20, seed=0)
    x, mu0 = model.predict(q), q + torch.tensor([0.0, 0.5], dtype=torch.float64)
    ruled = Perception([model]).infer({"ee_xyz": x}, mu0)
    assert (model.predict(ruled.mu) - x).norm(dim=1).max() < 1e-5


def test_levels_reaching_and_tracking_resolve_the_same_precision_for_the_same_model():
    models = [ToyVaryingArm(), ToyJoints()]                       # reaching drives the joints by default
    levels = Perception(models, LevelsConfig().perception).precisions
    reaching = aif_policy(ReachingConfig(), models, SimpleNamespace(actuation="position")).controller.perception
    timed, given = sensed(models, dict(TrackingConfig().noise), Clock(), {})   # simulated σ = 1 mm: Π = 1/σ²
    tracking = Tracker(timed, TrackerConfig(), precisions=given).perception.precisions
    assert levels["ee_xyz"] == reaching.precisions["ee_xyz"] == tracking["ee_xyz"] == EE_SENSOR
    assert "joints" not in levels and "joints" not in reaching.precisions      # a fixed Π stays the model's own


def test_goal_inference_weighs_the_senses_as_perception_does():
    model, mu = ToyVaryingArm(), planar_poses(8, seed=1)
    assert goal_precision([model], mu, 1.0) == pytest.approx(goal_precision([model], mu, 1.0, {"ee_xyz": EE_SENSOR}))
