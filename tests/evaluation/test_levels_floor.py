"""The levels' floor (evaluation/levels/floor.py): perception started at the true pose, a row per joint in the table,
summary.md, MLflow and the report's headline; a joint the model does not see is flagged; the demo reads it."""

from __future__ import annotations

import csv
import types

import numpy as np
import pytest
import torch

from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.specs import load_robot
from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels, run_levels
from bodyschema.evaluation.levels.floor import GAP
from bodyschema.evaluation.levels.targets import make_targets
from bodyschema.models.analytic import AnalyticModel

EXACT_DEG = 1e-6      # deg; an exact model's floor: the levels' update does not move from F's minimum at the truth


class ShiftedJoints(AnalyticModel):
    """planar2's joint encoders reading δ too high: g(z) = z + δ, so F's minimum at a true pose q lies at q − δ."""

    def __init__(self, shift_deg):
        super().__init__("planar2", "joints")
        self.shift = torch.deg2rad(torch.tensor(shift_deg, dtype=torch.float64))

    def _predict(self, z):
        return super()._predict(z + self.shift.to(z.dtype))


class BlindJoint(AnalyticModel):
    """planar2's joint encoders, but the reading of joint k does not follow joint k: a constant (the reading of a
    decoder fitted without seeing k) plus a weak ripple `ripple` in z_k (such a decoder's spurious dependence)."""

    def __init__(self, k: int, ripple: float = 0.05):
        super().__init__("planar2", "joints")
        self.k, self.ripple = k, ripple

    def _predict(self, z):
        out = super()._predict(z).clone()                                  # (B, 2) rad
        out[:, self.k] = 0.3 + self.ripple * torch.sin(3 * z[:, self.k])
        return out

    def _jacobian(self, z):
        jac = super()._jacobian(z).clone()                                 # (B, 2, 2)
        jac[:, self.k, self.k] = 3 * self.ripple * torch.cos(3 * z[:, self.k])
        return jac


def tiny(tmp_path, **changes) -> LevelsConfig:
    return LevelsConfig(**{"trials": 12, "runs": 2, "multistart": 0, "plots": False, "mlflow": False,
                           "progress": False, "out": tmp_path / "results" / "levels", **changes})


def test_every_run_has_a_floor_row_per_joint_and_every_level_its_gap_to_it(tmp_path):
    summary = run_levels(tiny(tmp_path, levels=(1, 2)), models=[AnalyticModel("planar2", "ee_xyz")])
    floor = summary.floor
    assert floor["level"] == "floor" and floor["runs"] == 2 and len(summary.floor_rows) == 2
    assert {"joint_err_deg/shoulder", "joint_err_deg/elbow", "joint_err_deg"} <= set(floor)
    assert [r["level"] for r in summary.table] == ["1", "2"], "the levels' table keeps its level rows"
    for row in summary.rows:                                               # each run's gap to its own floor
        own = next(f for f in summary.floor_rows if f["run"] == row["run"])
        assert row[GAP] == pytest.approx(row["joint_err_deg"] - own["joint_err_deg"])
    with open(summary.paths["summary_csv"], newline="") as f:
        assert [r["level"] for r in csv.DictReader(f)] == ["floor", "1", "2"]
    with open(summary.paths["runs_csv"], newline="") as f:
        assert [r["level"] for r in csv.DictReader(f)][:2] == ["floor", "floor"]
    text = summary.paths["summary_md"].read_text()
    assert "| floor |" in text and "joint_err_deg/elbow" in text and GAP in text
    assert "not observable" not in text
    assert summary.per_trial["floor"].shape == (24,)


def test_an_exact_model_has_a_zero_floor(tmp_path):
    summary, _ = measure_levels(tiny(tmp_path, levels=(1,)), [AnalyticModel("planar2", "joints")])
    assert summary.floor["joint_err_deg"] < EXACT_DEG
    assert all(summary.floor[f"joint_err_deg/{j}"] < EXACT_DEG for j in ("shoulder", "elbow"))


@pytest.mark.parametrize("shift_deg", [(0.0, 0.0), (1.0, -3.0)])
def test_the_floor_is_where_perception_started_at_the_truth_ends_the_models_own_bias(tmp_path, shift_deg):
    config, model = tiny(tmp_path, runs=1, levels=(1,), seed=3), ShiftedJoints(shift_deg)
    floor = measure_levels(config, [model])[0].floor
    # the run's targets; a belief stays inside the joint box, so q − δ is clipped to it
    q = make_targets(load_robot([model]), config.trials, eval_rng(config.seed, 0, "targets")).q      # (N, Dq) rad
    low, high = model.robot.sampling_ranges.T
    expected = np.rad2deg(np.abs(np.clip(q - np.deg2rad(shift_deg), low, high) - q)).mean()
    assert floor["joint_err_deg"] == pytest.approx(expected, abs=0.01)
    assert expected >= 0.9 * np.abs(shift_deg).mean(), "most targets are far from the box's edges"


def test_a_joint_the_model_does_not_see_has_a_large_floor_flagged_in_the_summary_the_others_none(tmp_path):
    summary = run_levels(tiny(tmp_path, levels=(2,)), models=[BlindJoint(k=1)])
    assert summary.floor["joint_err_deg/elbow"] > 10.0, "the ripple's minimum, not the truth (26.5° measured)"
    assert summary.floor["joint_err_deg/shoulder"] < EXACT_DEG
    text = summary.paths["summary_md"].read_text()
    assert f"- elbow: floor {summary.floor['joint_err_deg/elbow']:.2f}° > 2°: not observable by this model/camera" \
        in text
    assert "- shoulder" not in text
    from bodyschema.evaluation.report.headline import headline
    from bodyschema.evaluation.report.sections import find_sections
    section = find_sections(tmp_path / "results")[0][0]
    line = headline(section)
    assert "floor" in line and "not observable by this model/camera: elbow" in line and "Lfloor" not in line


def test_a_strictly_flat_joint_is_the_floors_limit_the_level_gap_shows_it(tmp_path):
    """F exactly flat along joint k: started at the truth the update never moves along it (floor ≈ 0); a level-2
    start stays off by its 5–10° there, all of it in the gap (floor.py's docstring)."""
    summary, _ = measure_levels(tiny(tmp_path, levels=(2,)), [BlindJoint(k=1, ripple=0.0)])
    assert summary.floor["joint_err_deg/elbow"] < EXACT_DEG
    assert summary.table[0]["joint_err_deg/elbow"] > 4.0 and summary.table[0][GAP] > 2.0


def test_the_floor_goes_to_mlflow_and_the_threshold_is_a_setting(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    summary = run_levels(tiny(tmp_path, levels=(1,), mlflow=True, unobservable_deg=60.0,
                              tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}"), models=[BlindJoint(k=1)])
    import mlflow
    metrics = mlflow.get_run(summary.run_id).data.metrics
    assert metrics["floor.joint_err_deg"] == pytest.approx(summary.floor["joint_err_deg"])
    assert any(k.startswith("floor.joint_err_deg") and "elbow" in k for k in metrics)
    assert metrics[f"L1.{GAP}"] == pytest.approx(summary.table[0][GAP])
    assert "not observable" not in summary.paths["summary_md"].read_text(), "its ~30° is below a 60° threshold"
    with pytest.raises(ValueError, match="unobservable_deg must be"):
        LevelsConfig(unobservable_deg=0.0)


def test_the_demo_reads_the_pixel_decoders_floor_from_its_levels_run(tmp_path, monkeypatch):
    from bodyschema import demo
    from bodyschema.demo_config import DemoConfig
    from bodyschema.evaluation.core import specs

    assert not hasattr(demo, "decoder_floor"), "computed once, by the levels"
    seen = {}
    monkeypatch.setattr(specs, "resolve_models", lambda *a: ["decoder"])
    monkeypatch.setattr(demo, "_evaluate", lambda *a: types.SimpleNamespace(floor={"joint_err_deg": 1.25}))
    monkeypatch.setattr(demo, "_models_section", lambda config, trained, floor: seen.setdefault("floor", floor))
    result = types.SimpleNamespace(registered_name="dec", model_version="1")
    assert demo._evaluate_pixel(DemoConfig(out=tmp_path), {"pixel": result, "encoder": result}) == "decoder"
    assert seen["floor"] == 1.25
