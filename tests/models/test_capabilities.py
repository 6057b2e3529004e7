"""What a model kind can do is read from its class (models/capabilities.py) by every stage, never from its name."""

import pytest
import torch

from bodyschema.evaluation.agency.benchmark import _precision
from bodyschema.evaluation.core.sensing import NoisySensor, through_noise
from bodyschema.models import kinds
from bodyschema.models.analytic import AnalyticModel
from bodyschema.models.mdn import MDNModel
from bodyschema.training import sweep
from bodyschema.training.config import TrainConfig
from bodyschema.training.sweep_config import SweepConfig
from tests.toy_models import ToyPlanarArm

SIGMA = 0.1   # m: the simulated sensor's noise


def test_the_sweep_offers_every_kind_scored_by_one_decoders_val_rmse_and_no_other():
    offered = set(sweep._sweepable())
    for kind in kinds.trainable():
        cls = kinds.model_class(kind.name)
        assert (kind.name in offered) == (not cls.has_members and not cls.encodes), kind.name
    assert {"gpr", "svgp", "sklearn-gpr", "mdn", "pixel"} <= offered


def test_the_sweep_asks_the_class_whether_it_is_sweepable(monkeypatch, tmp_path):
    monkeypatch.setattr(MDNModel, "sweepable", False)
    with pytest.raises(ValueError, match="KIND must be one of .*Got 'mdn'. Train mdn with `bodyschema train`"):
        sweep.plan(SweepConfig("mdn", tmp_path, grid=("lr=1e-3",)))


def test_several_modalities_are_refused_unless_the_kind_has_members(tmp_path):
    assert TrainConfig(model=kinds.get("multimodal").config_class(), data=tmp_path,
                       modality="ee_xyz,image").modalities == ("ee_xyz", "image")
    with pytest.raises(ValueError, match="modality must be one array name for model kind 'mdn'"):
        TrainConfig(model=kinds.get("mdn").config_class(), data=tmp_path, modality="ee_xyz,image")


def test_only_the_analytic_kind_is_exact():
    assert AnalyticModel.exact
    assert not any(kinds.model_class(k.name).exact for k in kinds.trainable())


def test_an_exact_model_is_read_at_the_sensor_noise_whatever_its_kind(monkeypatch):
    arm = ToyPlanarArm(precision=1e4)
    seen, fixed = through_noise([arm], {"ee_xyz": SIGMA}, {})
    assert isinstance(seen[0], NoisySensor) and fixed == {}
    z = torch.zeros(2, 2, dtype=torch.float64)
    assert _precision(arm, z, SIGMA)[0, 0].item() == pytest.approx(1 / (1e-4 + SIGMA ** 2))
    monkeypatch.setattr(ToyPlanarArm, "exact", True)
    seen, fixed = through_noise([arm], {"ee_xyz": SIGMA}, {})
    assert seen == [arm] and fixed == {"ee_xyz": pytest.approx(1 / SIGMA ** 2)}
    assert _precision(arm, z, SIGMA)[0, 0].item() == pytest.approx(1 / SIGMA ** 2)
