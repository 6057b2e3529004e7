"""Agency benchmark: the forward model predicts the robot's own movement exactly (noise-free: F = 0, AUC = 1), a
moved scene is not felt (joints alone cannot tell it from an own movement), an unknown sensory delay costs AUC and
knowing it restores it, the streams of each kind, and bad input refused before any work."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bodyschema.evaluation.agency.benchmark import AgencyConfig, predicted_free_energy, prepare, run_agency
from bodyschema.evaluation.agency.report import roc_rows
from bodyschema.evaluation.agency.streams import ALL, SELF, delayed, make_episodes, observe
from bodyschema.models.analytic import AnalyticModel

QUIET = {"mlflow": False, "progress": False, "plots": False}
EXACT = AgencyConfig(trials=12, steps=12, delays=(0.0, 0.2), proprio_noise=0.0, visual_noise=(("ee_pixel", 0.0),),
                     **QUIET)


def energies(config: AgencyConfig):
    robot, sensors = prepare(config, [AnalyticModel(config.robot, "ee_pixel")])
    episodes = make_episodes(config, robot, np.zeros((config.trials, robot.dq)))
    noise = {**dict(config.visual_noise), "joints": config.proprio_noise}
    out = {}
    for delay, lag in zip(config.delays, config.lags()):
        observed = observe(robot, [m.modality for m in sensors], episodes, lag, noise, config.seed)
        out[(delay, False)] = predicted_free_energy(sensors, episodes.predicted, observed, noise)
        out[(delay, True)] = predicted_free_energy(sensors, delayed(episodes.predicted, episodes.rest, lag),
                                                   observed, noise)
    return episodes, out


@pytest.fixture(scope="module")
def exact():
    return energies(EXACT)


def test_streams_of_each_kind(exact):
    episodes, _ = exact
    own, pushed, scene = (episodes.kind == k for k in (SELF, "pushed", "scene_moved"))
    assert own.sum() == EXACT.trials // 2 and pushed.any() and scene.any()
    moving = np.abs(episodes.seen - episodes.rest[:, None]).max(axis=(1, 2))
    assert (moving > 0.05).all(), "every episode shows a movement (rad)"
    assert np.array_equal(episodes.felt[pushed], episodes.seen[pushed]), "a pushed arm is felt moving"
    still = np.abs(episodes.felt[scene] - episodes.rest[scene][:, None]).max()
    assert still < 0.05 < np.abs(episodes.seen[scene] - episodes.rest[scene][:, None]).max(), \
        "a moved scene: the arm holds still while the view moves"
    assert np.array_equal(episodes.predicted[own], episodes.felt[own]), "the forward model is the arm's dynamics"


def test_without_noise_or_delay_an_own_movement_has_zero_free_energy_and_auc_is_one(exact):
    episodes, out = exact
    energy = out[(0.0, False)]
    own = episodes.kind == SELF
    for modality, f in energy.items():
        assert np.allclose(f[own], 0.0, atol=1e-9), modality
    assert (energy["ee_pixel"][~own].mean(axis=1) > 1.0).all(), "an imposed movement is seen against the prediction"
    rows, _ = roc_rows(EXACT, episodes.kind, episodes.failed, {(0.0, False): energy})
    by = {(r["source"], r["senses"]): r["auc"] for r in rows}
    assert by[("pooled", ALL)] == 1.0 and by[("pushed", "joints")] == 1.0
    assert by[("scene_moved", "joints")] == 0.5, "a moved scene is not felt: joints alone cannot tell it"


def test_an_unknown_delay_costs_auc_and_knowing_it_restores_it(exact):
    episodes, out = exact
    rows, _ = roc_rows(EXACT, episodes.kind, episodes.failed, out)
    auc = {(r["delay_s"], r["known_delay"]): r["auc"] for r in rows if r["source"] == "pooled" and r["senses"] == ALL}
    assert auc[(0.2, False)] < auc[(0.0, False)] == 1.0
    assert auc[(0.2, True)] == 1.0
    own = episodes.kind == SELF
    assert np.allclose(out[(0.2, True)]["joints"][own], 0.0, atol=1e-9), "a known delay is predicted exactly"


def test_bad_input_is_refused_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="delays"):
        AgencyConfig(steps=10, period=0.05, delays=(0.0, 0.5))             # 0.5 s = the whole episode
    with pytest.raises(ValueError, match="sources"):
        AgencyConfig(sources=("tickled",))
    with pytest.raises(ValueError, match="trials"):
        AgencyConfig(trials=3)
    config = replace(EXACT, out=tmp_path / "a")
    with pytest.raises(ValueError, match="model modalities"):
        run_agency(config, models=[AnalyticModel("nao_arm", "joints")])
    with pytest.raises(ValueError, match="robot 'nao_arm'"):
        run_agency(config, models=[AnalyticModel("planar2", "ee_pixel")])
    assert not (tmp_path / "a").exists(), "no run folder before the input is checked"


def test_a_short_run_writes_roc_tables_plots_and_its_mlflow_run(tmp_path):
    import mlflow
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    config = replace(EXACT, trials=6, steps=6, delays=(0.0, 0.1), plots=True, out=tmp_path / "runs", mlflow=True,
                     tracking_uri=uri)
    paths = run_agency(config)
    assert {"roc_csv", "episodes_csv", "summary", "roc_png", "auc_vs_delay_png", "free_energy_png",
            "models_csv"} <= set(paths)
    assert "delay=100ms known pooled" in paths["summary"].read_text()
    mlflow.set_tracking_uri(uri)
    run = mlflow.search_runs(experiment_names=[config.experiment]).iloc[0]
    assert run["metrics.delay0ms_pooled_all_senses.auc"] == 1.0
    assert run["params.delays"] == "(0.0, 0.1)"
