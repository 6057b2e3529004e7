"""One perception-method knob, resolved once (aif/perception_config.resolve) for perception, action and the tracker:
the same models and requested method give the update they gave before the knob was one (issue 34)."""

from __future__ import annotations

import dataclasses

import pytest

from bodyschema.aif.action import ActionConfig, VelocityController
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import DEFAULTS, PerceptionConfig, is_image, resolve
from bodyschema.aif.tracker import Tracker
from bodyschema.aif.tracker_config import TrackerConfig
from bodyschema.base import modalities
from tests.aif.toys import ToyBlobImage, ToyJoints
from tests.toy_models import ToyPlanarArm

IMAGE, VECTOR, MIXED = (ToyBlobImage,), (ToyPlanarArm, ToyJoints), (ToyBlobImage, ToyJoints)

# (models, requested method) → the update a Perception runs (a cold start: the levels, goal inference,
# self-recognition, a tracker's restart) and a controller's tick runs (warm: a few updates from the last belief)
TABLE = [
    (IMAGE, "auto", "adam+lm", "flow"), (VECTOR, "auto", "flow", "flow"), (MIXED, "auto", "adam+lm", "flow"),
    *[(models, method, method, method) for models in (IMAGE, VECTOR, MIXED)
      for method in ("flow", "lm", "adam", "adam+lm")],
]


def _models(kinds) -> list:
    return [kind() for kind in kinds]


def _controller(kinds, config: PerceptionConfig = DEFAULTS) -> VelocityController:
    models = _models(kinds)
    return VelocityController(models, config, ActionConfig(drive=(models[-1].modality,)))


@pytest.mark.parametrize("kinds, method, cold, warm", TABLE)
def test_the_requested_method_resolves_as_before_for_every_caller(kinds, method, cold, warm):
    config = PerceptionConfig(method=method)
    assert Perception(_models(kinds), config).config.method == cold
    assert _controller(kinds, config).perception.config.method == warm
    assert resolve(config, [m.modality for m in _models(kinds)]).method == cold


@pytest.mark.parametrize("kinds", [IMAGE, VECTOR, MIXED])
def test_above_order_0_auto_is_the_flow_for_every_caller(kinds):
    config = PerceptionConfig(order=1, prior="damping")
    assert Perception(_models(kinds), config).config.method == "flow"
    assert _controller(kinds, config).perception.config.method == "flow"


@pytest.mark.parametrize("kinds", [IMAGE, VECTOR, MIXED])
def test_step_control_auto_is_descent_at_order_0_unless_warm(kinds):
    assert Perception(_models(kinds)).config.flow.step_control == "descent"
    assert _controller(kinds).perception.config.flow.step_control == "none"


def test_the_tracker_frames_run_the_warm_update_under_descent_and_its_restarts_the_cold_one():
    assert TrackerConfig().perception.method == "flow" and TrackerConfig().perception.descends
    tracker = Tracker(_models(MIXED), TrackerConfig(budget=5, proposals=False))
    assert tracker.perception.config.method == "flow"
    assert tracker._restarts.config.method == "adam+lm"


def test_whether_a_modality_is_an_image_is_asked_of_its_record():
    second = dataclasses.replace(modalities.get("image"), name="wrist_image", array="wrist_image")
    modalities.register(second)
    try:
        assert is_image("wrist_image") and resolve(PerceptionConfig(), ["wrist_image", "joints"]).method == "adam+lm"
    finally:
        modalities.unregister("wrist_image")
    assert not is_image("wrist_image") and not is_image("ee_xyz") and not is_image("a_sensor_outside_the_table")
    assert resolve(PerceptionConfig(), ["wrist_image", "joints"]).method == "flow"
