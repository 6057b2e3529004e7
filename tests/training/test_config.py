"""TrainConfig validation, the typed hyper-parameters, the run-identity hash and the model factory."""

import pytest

from bodyschema.models import BodySpec
from bodyschema.models.configs import GPRConfig, MDNConfig, MultimodalConfig, PixelConfig
from bodyschema.training.config import TrainConfig, train_commands, untrained_model


def test_a_config_that_is_not_a_kinds_names_the_available_ones():
    with pytest.raises(ValueError, match=r"dict is not the config of a trainable model kind\. Use one of "
                                         r"\['GPRConfig', 'SVGPConfig', 'SklearnGPRConfig', 'MDNConfig'"):
        TrainConfig(model={"epochs": 3}, data="d.zarr")


def test_every_problem_is_reported_at_once():
    with pytest.raises(ValueError) as info:
        TrainConfig(model=MDNConfig(), data="d.zarr", seed=-1, val_fraction=1.5, max_train=0)
    message = str(info.value)
    assert "seed must be" in message and "val_fraction must be" in message and "max_train must be" in message


def test_default_modality_comes_from_the_kind():
    assert TrainConfig(model=PixelConfig(), data="d").modality == "image"
    assert TrainConfig(model=MultimodalConfig(), data="d").modalities == ("ee_xyz", "image")
    assert TrainConfig(model=MDNConfig(), data="d").modality == "ee_xyz"
    with pytest.raises(ValueError, match="Several modalities .* need `bodyschema train multimodal`"):
        TrainConfig(model=MDNConfig(), data="d", modality="ee_xyz,image")


def test_hyper_values_hold_every_hyper_parameter_as_json():
    config = TrainConfig(model=MDNConfig(epochs=5, hidden=(32, 32), mode="max"), data="d")
    assert config.kind == "mdn"
    assert config.hyper_values() == {**MDNConfig().to_kwargs(), "epochs": 5, "hidden": [32, 32], "mode": "max"}
    assert config.to_dict()["model"] == "mdn" and config.to_dict()["hyper"] == config.hyper_values()


def test_run_identity_ignores_where_results_go_but_not_what_is_trained(tmp_path):
    a = TrainConfig(model=MDNConfig(), data="d", run_root=tmp_path)
    b = TrainConfig(model=MDNConfig(), data="d", run_root=tmp_path, tracking_uri="http://127.0.0.1:1",
                    progress=False, experiment="other", register=False)
    assert a.run_dir("x") == b.run_dir("x")
    assert a.run_dir("x").name.startswith("mdn-ee_xyz-")
    assert a.run_dir("x") != a.run_dir("y"), "other data content → another run"
    assert a.run_dir("x") == TrainConfig(model=MDNConfig(), data="moved/d", run_root=tmp_path).run_dir("x"), \
        "the same content elsewhere is the same data"
    assert a.run_dir("x") != TrainConfig(model=MDNConfig(), data="d", run_root=tmp_path, seed=1).run_dir("x")
    assert a.run_dir("x") != TrainConfig(model=MDNConfig(epochs=3), data="d", run_root=tmp_path).run_dir("x")
    assert a.run_dir("x") == TrainConfig(model=MDNConfig(epochs=300), data="d", run_root=tmp_path).run_dir("x"), \
        "a default given explicitly is the same model"
    assert "hyper" in a.identity("x") and a.identity("x")["hyper"]["epochs"] == 300


def test_the_factory_passes_every_hyper_parameter_to_the_constructor(tiny_kind):
    from tests.training.tiny_model import TinyConfig

    body = BodySpec("r", ("a", "b"), (-1.0, -1.0), (1.0, 1.0))
    config = TrainConfig(model=TinyConfig(epochs=2, lr=0.1), data="d", modality="ee_xyz")
    model = untrained_model(config, body, {"ee_xyz": (3,)})
    assert isinstance(model, tiny_kind) and (model.epochs, model.lr) == (2, 0.1) and model.output_shape == (3,)
    with pytest.raises(ValueError, match="modality must be a single modality for model kind 'tiny'"):
        untrained_model(config, body, {"ee_xyz": (3,), "joints": (2,)})


def test_one_train_subcommand_per_trainable_kind():
    names = [name for name, _, _ in train_commands()]
    assert names == ["gpr", "svgp", "sklearn-gpr", "mdn", "pixel", "multimodal", "encoder"]
    assert all(description for _, _, description in train_commands())


def test_typed_values_are_checked_at_the_config(tmp_path):
    with pytest.raises(ValueError) as info:
        GPRConfig(lr=float("nan"), max_points=-1, adam_steps=True)
    message = str(info.value)
    assert "--lr must be a finite number ≥ 0. Got nan." in message
    assert "--max-points must be an integer ≥ 0. Got -1." in message
    assert "--adam-steps must be an integer ≥ 0. Got True." in message
    with pytest.raises(ValueError, match=r"--mode must be one of \['mean', 'max'\]. Got 'median'"):
        MDNConfig(mode="median")
    with pytest.raises(ValueError, match=r"--hidden must be a list of integers ≥ 1. Got \(32, 0\)"):
        MDNConfig(hidden=(32, 0))
    with pytest.raises(ValueError, match=r"--precisions must be pairs of a name and a finite number ≥ 0 or None"):
        MultimodalConfig(precisions={"image": float("inf")})
    assert PixelConfig(channels=None, refine=False).to_kwargs()["refine"] is False
