"""Closed-loop reaching on nao_arm with the analytic models: AIF reaches, failures stay in their episode,
bad input raises the house error, a seed reproduces the metrics."""

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from bodyschema.control.loop import rollout
from bodyschema.control.sim import control_substeps
from bodyschema.evaluation.core.sensing import Sensors
from bodyschema.evaluation.reaching import goal_pose
from bodyschema.evaluation.reaching.benchmark import ReachingConfig, aif_policy, prepare, run_reaching, simulate
from bodyschema.evaluation.reaching.goals import check_goal, make_goal
from bodyschema.evaluation.reaching.report import time_to_reach

SHORT = dict(trials=4, duration=1.5, mlflow=False, progress=False)


def read_rows(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reaching")
    return run_reaching(ReachingConfig(out=out, **SHORT))


def test_aif_reaches_pixel_goals_and_beats_standing_still(short_run):
    config = ReachingConfig(**SHORT)
    robot, _, modality, episodes, _ = prepare(config)
    standing = 1e3 * np.linalg.norm(robot.fk(episodes.q_start) - episodes.target_xyz, axis=1)   # (N,) mm
    standing_px = np.linalg.norm(robot.project(robot.fk(episodes.q_start)) - episodes.goal["ee_pixel"].numpy(), axis=1)
    aif = [r for r in read_rows(short_run["episodes_csv"]) if r["controller"] == "aif"]
    final = np.array([float(r["ee_err_mm"]) for r in aif])
    final_px = np.array([float(r["goal_err_px"]) for r in aif])
    assert modality == "ee_pixel"
    assert (final < 0.5 * standing).all()
    assert (final_px < 0.2 * standing_px).all() and not any(r["failed"] == "True" for r in aif)


def test_outputs_are_written(short_run):
    for key in ("episodes_csv", "summary_csv", "summary_md", "ee_error_png", "paths_png"):
        assert short_run[key].is_file() and short_run[key].stat().st_size > 0
    table = read_rows(short_run["summary_csv"])
    assert [r["controller"] for r in table] == ["aif", "pd"]
    assert "| aif |" in short_run["summary_md"].read_text()


def test_same_seed_reproduces_the_metrics_exactly(short_run, tmp_path):
    again = run_reaching(ReachingConfig(out=tmp_path, **SHORT))
    assert again["episodes_csv"].read_bytes() == short_run["episodes_csv"].read_bytes()


def test_nan_in_one_stream_fails_only_its_episode():
    config = ReachingConfig(**SHORT)
    robot, models, _, episodes, sensed = prepare(config)

    class Glitch(Sensors):                      # the camera returns NaN for episode 1 from the 10th tick on
        ticks = 0

        def read(self, arm):
            out = super().read(arm)
            self.ticks += 1
            if self.ticks >= 10:
                out["ee_pixel"] = out["ee_pixel"].clone()
                out["ee_pixel"][1] = float("nan")
            return out

    result = rollout(robot, aif_policy(config, models, robot), episodes.q_start, episodes.goal,
                     episodes.target_xyz, Glitch(sensed), ticks=60, substeps=control_substeps(50, 0.002))
    assert result.failed.tolist() == [False, True, False, False]
    assert "non-finite" in result.reasons[1]
    others = result.ee_err[-1, [0, 2, 3]]
    assert (others < result.ee_err[0, [0, 2, 3]]).all()


def test_time_to_reach_is_the_first_time_it_stays_inside():
    t = np.arange(5) * 0.1
    err = np.array([[5, 5, 5], [0.5, 5, 5], [5, 0.5, 5], [0.5, 0.5, 5], [0.5, 0.5, 5]])   # (T, B)
    reach = time_to_reach(t, err, 1.0)
    assert reach[0] == pytest.approx(0.3) and reach[1] == pytest.approx(0.2) and np.isnan(reach[2])


def test_bad_control_rate_raises():
    with pytest.raises(ValueError, match="control_hz"):
        control_substeps(33.0, 0.002)
    with pytest.raises(ValueError, match="control_hz"):
        control_substeps(1000.0, 0.002)                # faster than the simulator
    assert control_substeps(50.0, 0.002) == 10
    with pytest.raises(ValueError, match="control_hz"):
        run_reaching(ReachingConfig(control_hz=30.0, **SHORT))


def test_model_of_another_robot_raises():
    with pytest.raises(ValueError, match="robot 'nao_arm'"):
        prepare(ReachingConfig(models=("analytic:planar2:ee_xyz",), **SHORT))


def test_malformed_or_unreachable_goals_raise():
    config = ReachingConfig(**SHORT)
    robot, *_ = prepare(config)
    q = robot.sampling_ranges.mean(axis=1)[None]
    with pytest.raises(ValueError, match="ee_pixel goal"):
        check_goal(robot, "ee_pixel", torch.tensor([[-5.0, 10.0]]), (2,))           # outside the image
    with pytest.raises(ValueError, match="ee_pixel goal"):
        check_goal(robot, "ee_pixel", torch.zeros(1, 3), (2,))                      # wrong shape
    with pytest.raises(ValueError, match="finite"):
        check_goal(robot, "ee_xyz", torch.full((1, 3), float("nan")), (3,))
    with pytest.raises(ValueError, match="reach"):
        check_goal(robot, "ee_xyz", torch.tensor([[2.0, 0.0, 0.0]]), (3,))          # 2 m away
    with pytest.raises(ValueError, match="joint limits"):
        check_goal(robot, "joints", torch.full((1, 4), 3.0), (4,))
    check_goal(robot, "ee_xyz", make_goal(robot, "ee_xyz", q), (3,))                # a reachable one passes
    with pytest.raises(ValueError, match="goal"):
        ReachingConfig(goal="touch")
    with pytest.raises(ValueError, match="goal"):
        prepare(ReachingConfig(goal="ee_xyz", **SHORT))                             # no ee_xyz model


def test_panda_runs_the_torque_loop_and_its_pd_baseline_reaches(tmp_path):
    paths = run_reaching(ReachingConfig(robot="panda", trials=2, duration=1.5, out=tmp_path, mlflow=False,
                                        progress=False))
    rows = read_rows(paths["episodes_csv"])
    assert [r["controller"] for r in rows] == ["aif", "aif", "pd", "pd"]
    assert not any(r["failed"] == "True" for r in rows)
    assert all(r["success"] == "True" for r in rows if r["controller"] == "pd")
    with pytest.raises(ValueError, match="broken"):
        run_reaching(ReachingConfig(robot="panda", broken=("joints",), **SHORT))


def test_one_mlflow_run_with_the_outputs_as_artifacts(tmp_path, monkeypatch):
    import mlflow
    monkeypatch.chdir(tmp_path)                        # MLflow puts artifacts under ./mlartifacts
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    paths = run_reaching(ReachingConfig(trials=2, duration=0.5, baseline=False, progress=False, out=tmp_path / "out",
                                        tracking_uri=uri, experiment="test-reaching"))
    mlflow.set_tracking_uri(uri)
    runs = mlflow.search_runs(experiment_names=["test-reaching"])
    assert len(runs) == 1 and "metrics.aif.success" in runs.columns
    artifacts = {a.path for a in mlflow.MlflowClient().list_artifacts(runs.run_id[0])}
    assert artifacts == {p.name for p in paths.values()}


def test_planar2_with_the_analytic_model_reaches_every_target():
    """The velocity controller on planar2's soft servos, ee_xyz goals: every target within 1 cm (targets and starts
    in the middle 60 % of the ranges: a goal across a joint limit stalls any local descent)."""
    config = ReachingConfig(robot="planar2", trials=20, spread=0.6, baseline=False, mlflow=False, progress=False)
    _, _, modality, _, results, _ = simulate(config)
    final = results["aif"].ee_err[-1]                                                 # (B,) m
    assert modality == "ee_xyz" and not results["aif"].failed.any()
    assert (final < 0.01).all(), np.round(1e3 * final, 1)


def test_goal_inference_reaches_planar2_over_its_full_ranges():
    """Over the full joint ranges the goal's own attractor stalls at a joint limit where the goal needs the long way
    round; the pose imagined from several starts is reached along the straight joint-space path."""
    config = ReachingConfig(robot="planar2", trials=20, baseline=False, mlflow=False, progress=False)
    final = {}
    for mode in ("auto", "off"):
        robot, _, _, episodes, results, _ = simulate(replace(config, goal_inference=mode))
        final[mode] = results["aif"].ee_err[-1]                                         # (B,) m
        if mode == "auto":
            assert goal_pose.imagined_error_mm(robot, episodes, episodes.extra["imagined"]).max() < 0.1
    assert (final["auto"] < 0.01).all(), np.round(1e3 * final["auto"], 1)
    assert np.mean(final["off"] < 0.01) < 1.0


def test_goal_inference_settings_are_checked():
    with pytest.raises(ValueError, match="goal_inference"):
        ReachingConfig(goal_inference="maybe")
    with pytest.raises(ValueError, match="goal_starts"):
        ReachingConfig(goal_starts=0)
    with pytest.raises(ValueError, match="goal_inference"):                             # nothing to reach it through
        prepare(ReachingConfig(robot="panda", models=("analytic:panda:ee_xyz",), goal_inference="on", **SHORT))
    config = ReachingConfig(robot="panda", models=("analytic:panda:ee_xyz",), **SHORT)
    assert "imagined" not in prepare(config)[3].extra                                   # auto falls back quietly
    with pytest.raises(ValueError, match="encoder"):                                    # no image goal to start
        prepare(ReachingConfig(robot="panda", encoder="models:/some-encoder@champion", **SHORT))


def test_spread_out_of_range_raises():
    with pytest.raises(ValueError, match="spread"):
        ReachingConfig(spread=0.0)


def test_a_joint_space_depth_cue_lets_pixel_goals_reach_in_3d():
    """An ee_pixel goal leaves the depth open; fused with the target's joint pose seen through 4° of noise, every
    episode ends within 1 cm, better than the pixel alone and than the cue alone."""
    config = ReachingConfig(trials=10, baseline=False, mlflow=False, progress=False)
    final = {}
    for sigma in (0.0, 4.0):
        robot, _, _, episodes, results, _ = simulate(replace(config, depth_cue_deg=sigma))
        final[sigma] = results["aif"].ee_err[-1]                                       # (B,) m
    cue_alone = np.linalg.norm(robot.fk(episodes.goal["joints"].numpy()) - episodes.target_xyz, axis=1)
    assert (final[4.0] < 0.01).all(), np.round(1e3 * final[4.0], 1)
    assert np.mean(final[0.0] < 0.01) < 1.0 and np.mean(cue_alone < 0.01) < 1.0


def test_depth_cue_needs_a_joints_model_and_a_non_joint_goal():
    with pytest.raises(ValueError, match="depth_cue_deg"):
        prepare(ReachingConfig(goal="joints", depth_cue_deg=4.0, **SHORT))
    with pytest.raises(ValueError, match="depth_cue_deg"):
        prepare(ReachingConfig(models=("analytic:nao_arm:ee_pixel",), depth_cue_deg=4.0, **SHORT))
    with pytest.raises(ValueError, match="depth_cue_deg"):
        ReachingConfig(depth_cue_deg=-1.0)


def test_the_panda_aic_stays_selectable():
    config = ReachingConfig(robot="panda", panda_controller="aic", trials=2, duration=0.2, baseline=False,
                            mlflow=False, progress=False)
    _, models, _, _, results, _ = simulate(config)
    assert not results["aif"].failed.any() and {m.modality for m in models} == {"ee_xyz", "joints"}
    with pytest.raises(ValueError, match="panda_controller"):
        ReachingConfig(robot="panda", panda_controller="mpc")
