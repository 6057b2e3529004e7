"""Issue 22: a model kind's capabilities are declared on its class and hold there; a modality is one table row.

Every capability a shipped class declares is backed by what the readers need (the memory guards size it, the
encoder encodes, the multimodal model has members), and a class that does not declare `exports_onnx` is refused
by the exporter by name. The modality table's shapes are those the simulator's sensors and the exact forward
kinematics really produce.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bodyschema.base import modalities
from bodyschema.models import kinds
from bodyschema.models.scaling import BodySpec

BODY = BodySpec("planar2", ("j0", "j1"), (-1.0, -1.0), (1.0, 1.0))
IMAGE = (16, 24)
TRAINABLE = [k.name for k in kinds.trainable() if k.module.startswith("bodyschema.models.")]


def _untrained(name: str):
    from bodyschema.training.config import TrainConfig, untrained_model

    config = TrainConfig(model=kinds.get(name).config_class(), data="unused.zarr")
    shapes = {m: IMAGE if m == "image" else (3,) for m in config.modalities}
    return untrained_model(config, BODY, shapes)


@pytest.mark.parametrize("name", TRAINABLE)
def test_each_declared_capability_is_backed_by_what_its_readers_use(name):
    from bodyschema.training import guards

    model = _untrained(name)
    if model.network:
        params, activations = guards.net_sizes(model)
        assert params > 0 and activations > 0, "the network guard sizes it from `_factory`"
    if model.gp_memory is not None:
        assert guards.gp_peak_bytes(name, 2000, 10, 3) == 4 * guards.gp_peak_bytes(name, 1000, 10, 3), "n²"
    assert (model.gp_memory is not None) + model.network == 1, "exactly one memory guard applies"
    if model.has_members:
        assert model.members and all(m.exports_onnx for m in model.members.values())
    if model.encodes:
        assert callable(model.encode) and model.image_shape == IMAGE


@pytest.mark.parametrize("name", ["sklearn-gpr", "multimodal"])
def test_a_model_that_does_not_declare_export_is_refused_by_name(name):
    from bodyschema.models.onnx_export import check_exportable, exportable_kinds

    model = _untrained(name)
    assert not model.exports_onnx and model.onnx_hint, "a kind that does not export says what to do instead"
    with pytest.raises(ValueError, match="model kind must be one of .* to export ONNX. Got") as info:
        check_exportable(model)
    assert str(info.value).endswith(model.onnx_hint)
    assert "gpr" in exportable_kinds() and "sklearn-gpr" not in exportable_kinds()


@pytest.mark.parametrize("name", modalities.KINEMATIC)
def test_the_table_shapes_are_what_the_sensors_and_the_exact_kinematics_produce(name):
    from bodyschema.datagen.body.robot import Robot
    from bodyschema.evaluation.core.sensing import sense
    from bodyschema.models.analytic import AnalyticModel

    robot = Robot.load("planar2")
    q = np.zeros((5, robot.dq))
    expected = modalities.shape_of(name, robot.dq)
    assert sense(robot, name, q).shape == (5, *expected)
    oracle = AnalyticModel("planar2", name)
    assert tuple(oracle.predict(torch.zeros(5, robot.dq, dtype=torch.float64)).shape) == (5, *expected)
    assert oracle.fixed_precision == modalities.MODALITIES[name].precision


def test_the_joints_are_found_by_their_array_name_and_an_unknown_modality_names_the_known_ones():
    assert modalities.get("q") is modalities.MODALITIES["joints"]
    assert modalities.unit("image") == modalities.IMAGE_UNIT and modalities.unit("smell", "?") == "?"
    with pytest.raises(ValueError, match=r"Modality 'smell' is not known. Choose one of \['joints', 'ee_xyz'"):
        modalities.get("smell")
