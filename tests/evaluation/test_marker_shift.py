"""Marker shift (adaptation a): the unshifted loop holds its goal, a shifted marker pulls the hand so that the seen
marker nears the goal — more when vision is trusted more, as the linear steady state predicts — failures stay in
their episode, bad input raises the house error, and a seed reproduces the written numbers byte for byte."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from bodyschema.control.sim import control_substeps
from bodyschema.evaluation.adaptation.marker_shift import (
    MarkerShiftConfig,
    goal_poses,
    marker_offsets,
    run_marker_shift,
    simulate,
)
from bodyschema.evaluation.adaptation.marker_shift_report import episode_rows, predicted_correction
from bodyschema.evaluation.core.specs import load_robot
from bodyschema.models.analytic import AnalyticModel

# 1 s after the shift settles the loop for these precisions (settling ≈ 0.3 s); 100 Hz keeps the sampled loop stable.
SHORT = dict(trials=2, duration=1.2, shift_time=0.2, control_rate=100.0, mlflow=False, progress=False)


@pytest.fixture(scope="module")
def models():
    return [AnalyticModel("nao_arm", "joints"), AnalyticModel("nao_arm", "ee_pixel")]


@pytest.fixture(scope="module")
def robot(models):
    return load_robot(models)


def _run(robot, models, shifts, precision, **overrides):
    config = MarkerShiftConfig(shifts=shifts, **{**SHORT, **overrides})
    q_goal = goal_poses(robot, config.trials, config.seed)
    names = [s for s in shifts for _ in range(config.trials)]
    q0 = np.tile(q_goal, (len(shifts), 1))
    series = simulate(robot, models, config, q0, marker_offsets(names, config.offset), precision)
    return names, q0, series


def test_without_a_shift_the_hand_stays_at_the_goal(robot, models):
    _, _, s = _run(robot, models, ("none",), 10.0)
    drift_mm = 1e3 * np.linalg.norm(s["hand_xyz"] - s["goal_xyz"], axis=2)       # (T+1, B)
    assert drift_mm.max() < 0.05, f"the unshifted loop must hold its goal (servos start at rest): {drift_mm.max()} mm"
    assert np.abs(s["marker_px"] - s["goal_px"]).max() < 0.01
    assert not s["failed"].any()


def test_a_shifted_marker_moves_the_hand_toward_bringing_the_seen_marker_to_the_goal(robot, models):
    shifts = ("left", "right", "forearm")
    moved = {}
    for precision in (0.3, 3.0):
        names, q0, s = _run(robot, models, shifts, precision)
        k = int(s["shift_tick"])
        seen = s["marker_px"][k] - s["hand_px"][k]                                # (B, 2) px, the visual conflict
        jac = robot.project_jacobian(robot.fk(q0)) @ robot.jacobian(q0)
        predicted = predicted_correction(jac, seen, precision, models[0].fixed_precision)
        rows = episode_rows(s, names, precision, predicted)
        for r in rows:
            assert not r["failed"] and r["hold_drift_mm"] < 0.05, r
            assert r["seen_shift_px"] > 1.0                                       # the shift is visible
            assert r["marker_err_px"] < r["seen_shift_px"], f"seen marker must approach the goal: {r}"
            assert 0 < r["correction"] < 1, r                                     # toward it, not past it
            assert r["correction"] == pytest.approx(r["predicted_correction"], rel=0.3), r   # linear steady state
        moved[precision] = np.array([r["hand_move_mm"] for r in rows])
    assert (moved[3.0] > 2 * moved[0.3]).all(), f"higher visual precision must move the hand more: {moved}"


def test_a_failing_episode_is_marked_and_the_others_go_on(robot, models):
    config = MarkerShiftConfig(shifts=("left",), **SHORT)
    q0 = goal_poses(robot, 2, config.seed)
    offsets = marker_offsets(["left", "left"], config.offset)
    offsets[1] = np.nan                                                           # the marker leaves the scene
    s = simulate(robot, models, config, q0, offsets, 1.0)
    assert s["failed"].tolist() == [False, True] and "non-finite" in s["reasons"][1]
    assert np.isfinite(s["hand_xyz"]).all() and np.abs(s["marker_px"][-1, 0] - s["goal_px"][0]).max() > 0


def test_bad_input_raises_the_house_error(robot, models):
    with pytest.raises(ValueError, match="shifts must be .*Got .*'sideways'"):
        MarkerShiftConfig(shifts=("left", "sideways"))
    with pytest.raises(ValueError, match="shift must be"):
        marker_offsets(["up"], 0.03)
    for bad in (dict(shift_time=5.0, duration=4.0), dict(visual_precisions=(1.0, -1.0)), dict(goal="xyz"),
                dict(trials=0)):
        with pytest.raises(ValueError, match="must be"):
            MarkerShiftConfig(**bad)
    with pytest.raises(ValueError, match="control_rate must be"):
        control_substeps(300.0, robot.model.opt.timestep, "control_rate")      # 1.67 MuJoCo steps
    with pytest.raises(ValueError, match="models must be"):
        run_marker_shift(MarkerShiftConfig(**SHORT), models=[models[1]])          # no proprioception: no conflict


def test_run_writes_everything_logs_mlflow_and_the_same_seed_reproduces_the_numbers(tmp_path, monkeypatch, models):
    monkeypatch.chdir(tmp_path)
    common = dict(SHORT, trials=1, duration=0.6, visual_precisions=(0.3, 3.0), shifts=("none", "forearm"))
    first = run_marker_shift(MarkerShiftConfig(out=tmp_path / "a", **{**common, "mlflow": True},
                                               tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}"), models)
    again = run_marker_shift(MarkerShiftConfig(out=tmp_path / "b", **common), models)
    for name, path in first.items():
        assert path.is_file() and path.stat().st_size > 0, name
    for name in ("summary_csv", "episodes_csv", "timeseries_csv", "summary_md"):
        assert first[name].read_bytes() == again[name].read_bytes(), f"{name} differs between two seeded runs"
    table = list(csv.DictReader(first["summary_csv"].open()))
    assert [(r["shift"], float(r["visual_precision"])) for r in table] == [
        ("none", 0.3), ("forearm", 0.3), ("none", 3.0), ("forearm", 3.0)]
    import mlflow
    runs = mlflow.search_runs(experiment_names=["bodyschema-adaptation"])
    assert len(runs) == 1 and "metrics.forearm.pv3.hand_move_mm" in runs.columns
