"""Jupiter adaptation benchmark: control rate, the PD baseline, the AIC on the panda, failures, outputs."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from bodyschema.aif.aic import AICController
from bodyschema.aif.aic_config import AICConfig
from bodyschema.control.pd import PDController
from bodyschema.datagen.body.robot import Robot
from bodyschema.evaluation.adaptation.jupiter import (
    READY,
    JupiterConfig,
    control_substeps,
    errors,
    run_jupiter,
    sample_poses,
    simulate,
)
from bodyschema.evaluation.core.runs import read_run_record
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.models.analytic import AnalyticModel

QUIET = dict(mlflow=False, progress=False)


@pytest.fixture(scope="module")
def panda():
    return Robot.load("panda", actuators="torque")


def short(duration: float, **kw) -> JupiterConfig:
    return JupiterConfig(duration=duration, switch_time=duration - 0.1, steady_window=0.1, **QUIET, **kw)


# ---- config -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("rate", [300.0, 1000.0, 0.0, float("nan")])
def test_a_control_rate_that_cannot_be_met_raises(rate):
    with pytest.raises(ValueError, match="control_rate"):
        JupiterConfig(control_rate=rate)


def test_control_substeps_divide_the_mujoco_step():
    assert [control_substeps(r, 0.002) for r in (500.0, 250.0, 100.0)] == [1, 2, 5]


def test_a_model_of_another_robot_raises_before_simulating(tmp_path):
    with pytest.raises(ValueError, match="ee_xyz model body"):
        run_jupiter(JupiterConfig(out=tmp_path, **QUIET), models=[AnalyticModel("nao_arm", "ee_xyz")])


def test_goals_and_starts_are_seeded_and_above_the_floor(panda):
    a = sample_poses(panda, 6, 0.4, eval_rng(3, 0, "targets"))
    np.testing.assert_array_equal(a, sample_poses(panda, 6, 0.4, eval_rng(3, 0, "targets")))
    assert (panda.fk(a)[:, 2] > 0.15).all() and (np.abs(a - READY) <= 0.4 + 1e-12).all()


# ---- controllers on the panda -------------------------------------------------------------------------------
def test_pd_with_earth_gravity_compensation_holds_a_pose_on_earth(panda):
    poses = sample_poses(panda, 2, 0.4, eval_rng(0, 0, "starts"))
    config = short(1.0)
    sim = simulate(panda, PDController("panda"), [], poses, poses, config)
    deviation = np.rad2deg(np.abs(sim["q"] - poses[None])).max(axis=(1, 2))  # (T,) deg
    earth, jupiter = sim["t"] < config.switch_time, sim["t"] > config.switch_time + 0.05
    assert deviation[earth].max() < 0.01, f"the PD drifted {deviation[earth].max():.3g}° from a pose it should hold"
    assert deviation[jupiter].min() > 0.1, "on Jupiter the Earth-tuned compensation falls short and the arm sags"
    assert not sim["failed"].any()


@pytest.mark.parametrize("extra", [False, True], ids=["joints", "joints+ee_xyz"])
def test_aic_reduces_the_joint_error_to_a_goal_on_the_panda(panda, extra):
    goals = sample_poses(panda, 2, 0.3, eval_rng(1, 0, "targets"))
    starts = sample_poses(panda, 2, 0.3, eval_rng(1, 0, "starts"))
    models = [AnalyticModel("panda", "ee_xyz")] if extra else []
    controller = AICController(models, AICConfig(), panda.model.actuator_ctrlrange)
    sim = simulate(panda, controller, models, starts, goals, short(2.0))
    joint, _ = errors(panda, sim["q"], goals)                                  # (T, B) deg
    assert (joint[-1] < 0.3 * joint[0]).all(), f"error {joint[0]} → {joint[-1]} deg"
    assert not sim["failed"].any()


class NaNOnce:
    """Wraps a controller and feeds it a NaN joint reading for episode 0 at one tick (a glitching encoder)."""

    def __init__(self, controller, tick: int):
        self.controller, self.tick, self.calls = controller, tick, 0

    def reset(self, q, qd, goal):
        self.controller.reset(q, qd, goal)

    def act(self, q, qd, observations, dt):
        self.calls += 1
        if self.calls == self.tick:
            q = q.copy()
            q[0, 0] = np.nan
        return self.controller.act(q, qd, observations, dt)

    failed = property(lambda self: self.controller.failed)
    reasons = property(lambda self: self.controller.reasons)


def test_an_episode_failing_mid_run_is_marked_and_the_others_go_on(panda):
    goals = sample_poses(panda, 2, 0.3, eval_rng(2, 0, "targets"))
    starts = sample_poses(panda, 2, 0.3, eval_rng(2, 0, "starts"))
    controller = NaNOnce(AICController([], AICConfig(), panda.model.actuator_ctrlrange), tick=20)
    sim = simulate(panda, controller, [], starts, goals, short(1.0))
    assert sim["failed"].tolist() == [True, False]
    assert "non-finite q" in sim["reasons"][0] and sim["reasons"][1] is None
    joint, _ = errors(panda, sim["q"], goals)
    assert joint[-1, 1] < 0.5 * joint[0, 1], "the healthy episode kept converging"


# ---- the benchmark end to end -------------------------------------------------------------------------------
def test_run_jupiter_writes_reproducible_tables_plots_and_an_mlflow_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    base = dict(trials=2, duration=0.4, switch_time=0.2, steady_window=0.1, control_rate=100.0, progress=False)
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    paths = run_jupiter(JupiterConfig(out=tmp_path / "a", tracking_uri=uri, **base))
    again = run_jupiter(JupiterConfig(out=tmp_path / "b", mlflow=False, **base))
    for name in ("summary_csv", "summary_md", "episodes_csv", "timeseries_csv", "errors_png", "trajectories_png"):
        assert paths[name].is_file() and paths[name].stat().st_size > 0
    for name in ("summary_csv", "episodes_csv", "timeseries_csv"):
        assert paths[name].read_bytes() == again[name].read_bytes(), f"{name} differs between two seeded runs"
    with open(paths["summary_csv"]) as f:
        rows = list(csv.DictReader(f))
    assert [r["controller"] for r in rows] == ["PD + g(q) on Earth", "AIC joints", "AIC joints + ee_xyz"]
    assert "24.79" in paths["summary_md"].read_text() and "(torque panda)" in paths["summary_md"].read_text()
    assert read_run_record(paths["summary_csv"].parent)["robot"] == JupiterConfig.robot == "panda"
    import mlflow
    runs = mlflow.search_runs(experiment_names=["bodyschema-adaptation"])
    assert len(runs) == 1 and "metrics.AIC joints.joint_err_after_deg" in runs.columns
