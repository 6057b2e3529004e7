"""TrainConfig validation, hyper-parameter parsing, the run-identity hash and the model-kind factory."""

import pytest

from bodyschema.models import BodySpec
from bodyschema.training.config import MODEL_KINDS, TrainConfig, build_model, model_class


def test_unknown_kind_lists_the_available_ones():
    with pytest.raises(ValueError, match=r"Model kind 'xgb' is not available\. Choose one of \[.*'gpr'.*'mdn'"):
        TrainConfig(model="xgb", data="d.zarr")
    with pytest.raises(ValueError, match="Model kind 'xgb' is not available"):
        model_class("xgb")


def test_every_problem_is_reported_at_once():
    with pytest.raises(ValueError) as info:
        TrainConfig(model="mdn", data="d.zarr", seed=-1, val_fraction=1.5, max_train=0)
    message = str(info.value)
    assert "seed must be" in message and "val_fraction must be" in message and "max_train must be" in message


def test_defaults_and_hyper_parsing():
    assert TrainConfig(model="pixel", data="d").modality == "image"
    assert TrainConfig(model="multimodal", data="d").modalities == ("ee_xyz", "image")
    with pytest.raises(ValueError, match="Several modalities .* need --model multimodal"):
        TrainConfig(model="mdn", data="d", modality="ee_xyz,image")
    config = TrainConfig(model="mdn", data="d", hyper={"epochs": "5", "lr": "1e-3", "hidden": "[32, 32]",
                                                        "mode": "max"})
    assert config.modality == "ee_xyz"
    assert config.hyper_values() == {"epochs": 5, "lr": 1e-3, "hidden": (32, 32), "mode": "max"}


def test_run_identity_ignores_where_results_go_but_not_what_is_trained(tmp_path):
    a = TrainConfig(model="mdn", data="d", run_root=tmp_path)
    b = TrainConfig(model="mdn", data="d", run_root=tmp_path, tracking_uri="http://127.0.0.1:1", progress=False,
                    experiment="other", register=False)
    assert a.run_dir("x") == b.run_dir("x")
    assert a.run_dir("x") != a.run_dir("y"), "other data content → another run"
    assert a.run_dir("x") == TrainConfig(model="mdn", data="moved/d", run_root=tmp_path).run_dir("x"), \
        "the same content elsewhere is the same data"
    assert a.run_dir("x") != TrainConfig(model="mdn", data="d", run_root=tmp_path, seed=1).run_dir("x")
    assert a.run_dir("x") != TrainConfig(model="mdn", data="d", run_root=tmp_path,
                                         hyper={"epochs": "3"}).run_dir("x")


def test_factory_builds_known_kinds_and_names_wrong_hyper_parameters(tiny_kind):
    body = BodySpec("r", ("a", "b"), (-1.0, -1.0), (1.0, 1.0))
    model = build_model("tiny", body, {"ee_xyz": (3,)}, {"epochs": 2})
    assert isinstance(model, tiny_kind) and model.epochs == 2 and model.output_shape == (3,)
    with pytest.raises(ValueError, match=r"hyper must be names accepted by TinyModel: \['epochs', 'lr'\]"):
        build_model("tiny", body, {"ee_xyz": (3,)}, {"epoch": 2})
    assert {"gpr", "sklearn-gpr", "mdn", "pixel", "multimodal"} <= set(MODEL_KINDS)
