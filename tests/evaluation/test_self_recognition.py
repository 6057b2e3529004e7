"""Self-recognition benchmark: rank AUC and ROC, the streams of each source, failures per episode, determinism,
and a short benchmark end to end where the robot tells its own body from a second arm."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
import torch

from bodyschema.evaluation.self_recognition.benchmark import (NoisySensor, SelfRecognitionConfig, prepare,
                                                             run_self_recognition, score_episodes)
from bodyschema.evaluation.self_recognition.report import auc, average_ranks, best_threshold, roc_curve
from bodyschema.evaluation.self_recognition.streams import episode_kinds, make_episodes, mirror
from bodyschema.evaluation.core.sensing import sense
from bodyschema.models.analytic import AnalyticModel

SHORT = SelfRecognitionConfig(trials=24, steps=4, mlflow=False, progress=False, plots=False)


@pytest.fixture(scope="module")
def pixel_model():
    return AnalyticModel("nao_arm", "ee_pixel")


@pytest.fixture(scope="module")
def setup(pixel_model):
    return prepare(SHORT, [pixel_model])                            # robot, perception, visual modalities


@pytest.fixture(scope="module")
def short_run(setup):
    robot, perception, visual = setup
    episodes = make_episodes(SHORT, robot, visual)
    return episodes, score_episodes(perception, episodes, visual, progress=False)


# ---- AUC and ROC ----------------------------------------------------------------------------------------
def brute_force_auc(s: np.ndarray, o: np.ndarray) -> float:
    pairs = o[None, :] - s[:, None]                                   # (S, O)
    return float(((pairs > 0) + 0.5 * (pairs == 0)).mean())


@pytest.mark.parametrize("seed", range(5))
def test_auc_equals_the_pairwise_count_with_ties(seed):
    rng = np.random.default_rng(seed)
    s, o = rng.integers(0, 8, size=rng.integers(1, 30)), rng.integers(2, 10, size=rng.integers(1, 30))
    assert auc(s, o) == pytest.approx(brute_force_auc(s, o), abs=1e-12)
    assert auc(o, s) == pytest.approx(1.0 - auc(s, o), abs=1e-12)


def test_average_ranks_share_ties_and_sum_to_the_triangle_number():
    values = np.random.default_rng(0).integers(0, 5, size=50)
    ranks = average_ranks(values)
    assert ranks.sum() == pytest.approx(50 * 51 / 2)
    for v in np.unique(values):
        assert np.ptp(ranks[values == v]) == 0                        # ties share one rank
        assert ranks[values == v][0] == pytest.approx((values < v).sum() + ((values == v).sum() + 1) / 2)


def test_roc_runs_from_origin_to_one_and_its_area_is_the_auc():
    rng = np.random.default_rng(1)
    s, o = rng.normal(0.0, 1.0, 60).round(1), rng.normal(1.0, 1.0, 50).round(1)   # rounded: ties
    roc = roc_curve(s, o)
    assert (roc["fpr"][0], roc["tpr"][0], roc["fpr"][-1], roc["tpr"][-1]) == (0, 0, 1, 1)
    assert (np.diff(roc["fpr"]) >= 0).all() and (np.diff(roc["tpr"]) >= 0).all()
    assert np.trapezoid(roc["tpr"], roc["fpr"]) == pytest.approx(auc(s, o), abs=1e-12)
    best = best_threshold(roc)
    assert best["tpr"] == pytest.approx((s <= best["threshold"]).mean())
    assert best["fpr"] == pytest.approx((o <= best["threshold"]).mean())
    assert best["tpr"] - best["fpr"] == pytest.approx(np.max(roc["tpr"] - roc["fpr"]))


# ---- sensors ---------------------------------------------------------------------------------------------
class LearnedPixel(AnalyticModel):
    kind = "learned"                                                  # stands for any non-exact model


def test_sensor_noise_adds_to_a_learned_models_variance_and_sets_an_exact_models_precision():
    config = replace(SHORT, visual_noise=(("ee_pixel", 0.5),), proprio_noise=0.1)
    learned = LearnedPixel("nao_arm", "ee_pixel", precision=4.0)
    _, perception, _ = prepare(config, [learned])
    joints, seen = perception.models
    z = torch.zeros(3, 4, dtype=torch.float64)
    assert isinstance(seen, NoisySensor) and perception.precisions == {"joints": pytest.approx(100.0)}
    torch.testing.assert_close(1.0 / seen.precision(z), 1.0 / learned.precision(z) + 0.25)
    torch.testing.assert_close(seen.predict(z), learned.predict(z))
    _, exact, _ = prepare(config, [AnalyticModel("nao_arm", "ee_pixel")])
    assert exact.precisions == {"joints": pytest.approx(100.0), "ee_pixel": pytest.approx(4.0)}


# ---- the streams ----------------------------------------------------------------------------------------
def test_episodes_are_half_self_and_the_others_split_over_the_sources():
    kinds = episode_kinds(201, ("second_arm", "delayed", "mirrored"))
    assert (kinds == "self").sum() == 100
    counts = [(kinds == k).sum() for k in ("second_arm", "delayed", "mirrored")]
    assert sum(counts) == 101 and max(counts) - min(counts) <= 1


def test_mirrored_views_are_reflections_that_agree_between_3d_and_pixels(setup):
    robot = setup[0]
    q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(16, robot.dq))
    for modality in ("ee_pixel", "ee_xyz"):
        x = sense(robot, modality, q)
        np.testing.assert_allclose(mirror(robot, modality, mirror(robot, modality, x)), x, atol=1e-12)
        assert not np.allclose(mirror(robot, modality, x), x)
    np.testing.assert_allclose(robot.project(mirror(robot, "ee_xyz", sense(robot, "ee_xyz", q))),
                               mirror(robot, "ee_pixel", sense(robot, "ee_pixel", q)), atol=1e-9)


def test_streams_show_own_body_late_body_or_another_arm(setup):
    robot, _, visual = setup
    config = replace(SHORT, steps=8, proprio_noise=0.0, visual_noise=())
    episodes = make_episodes(config, robot, visual)
    lag = round(config.delay / episodes.period)
    seen = episodes.visual["ee_pixel"]                                # (N, T, 2) px, noise-free
    mine = sense(robot, "ee_pixel", episodes.q.reshape(-1, robot.dq)).reshape(seen.shape)
    kind = episodes.kind
    np.testing.assert_allclose(seen[kind == "self"], mine[kind == "self"], atol=1e-4)
    np.testing.assert_allclose(seen[kind == "delayed"][:, lag:], mine[kind == "delayed"][:, :-lag], atol=1e-4)
    assert not np.allclose(seen[kind == "second_arm"], mine[kind == "second_arm"], atol=1.0)
    np.testing.assert_array_equal(episodes.proprio, episodes.q)
    low, high = robot.sampling_ranges.T
    assert ((episodes.q >= low) & (episodes.q <= high)).all()


def test_image_streams_are_rendered_frames_scaled_as_training_data_and_flipped_in_the_mirror():
    from bodyschema.datagen.robot import Robot
    from bodyschema.models.scaling import IMAGE_SCALE
    robot = Robot.load("nao_arm", image_size=(14, 20))
    config = replace(SHORT, trials=6, steps=2, visual_noise=(), sources=("mirrored",))
    episodes = make_episodes(config, robot, ["image"])
    frames = robot.render(episodes.q.reshape(-1, robot.dq)).reshape(6, 2, 14, 20) / IMAGE_SCALE
    mirrored = episodes.kind == "mirrored"
    np.testing.assert_allclose(episodes.visual["image"][~mirrored], frames[~mirrored], atol=1e-6)
    np.testing.assert_allclose(episodes.visual["image"][mirrored], frames[mirrored][..., ::-1], atol=1e-6)
    robot.close()


def test_an_image_model_runs_the_benchmark_on_frames_from_its_own_camera(tmp_path, pixel_model):
    from bodyschema.datagen.robot import Robot
    from bodyschema.models.pixel import PixelDecoder
    torch.set_num_threads(1)
    robot = Robot.load("nao_arm", image_size=(14, 20))
    q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(32, robot.dq))
    decoder = PixelDecoder(pixel_model.body, "image", (14, 20), fc_hidden=8, channels=(4,), epochs=2, batch_size=32)
    decoder.fit(q, robot.render(q) / 255.0, progress=False)
    robot.close()
    paths = run_self_recognition(replace(SHORT, trials=6, steps=2, out=tmp_path), models=[decoder])
    episodes = list(csv.DictReader(paths["episodes_csv"].open()))
    assert len(episodes) == 6 and not any(e["failed"] == "True" for e in episodes)
    assert all(np.isfinite(float(e["score_visual"])) for e in episodes)


# ---- failures, errors, determinism ----------------------------------------------------------------------
def test_a_nan_in_one_episode_fails_only_that_episode(setup, short_run):
    robot, perception, visual = setup
    clean_episodes, clean = short_run
    episodes = make_episodes(SHORT, robot, visual)
    episodes.visual["ee_pixel"][3, 2, 0] = np.nan
    scores = score_episodes(perception, episodes, visual, progress=False)
    assert np.flatnonzero(scores.failed).tolist() == [3]
    assert "ee_pixel" in scores.reason[3] and "frame 2" in scores.reason[3]
    assert np.isnan(scores.score()[3])
    others = np.arange(len(scores.failed)) != 3
    np.testing.assert_allclose(scores.score()[others], clean.score()[others], rtol=1e-9)


def test_a_model_of_another_robot_raises_the_house_error(tmp_path):
    with pytest.raises(ValueError, match="model body must be robot 'nao_arm'.*Got 'planar2'"):
        run_self_recognition(replace(SHORT, out=tmp_path), models=[AnalyticModel("planar2", "ee_pixel")])
    with pytest.raises(ValueError, match="model modalities must be"):
        prepare(SHORT, [AnalyticModel("nao_arm", "joints")])


@pytest.mark.parametrize("bad", [dict(trials=4), dict(sources=("twin",)), dict(score="mean"),
                                 dict(delay=0.01), dict(visual_noise=(("ee_pixel", -1.0),))])
def test_bad_config_raises_the_house_error(bad):
    with pytest.raises(ValueError, match="must be"):
        replace(SHORT, **bad)


def test_the_same_seed_reproduces_the_scores_exactly(setup, short_run):
    robot, perception, visual = setup
    episodes, scores = short_run
    again = score_episodes(perception, make_episodes(SHORT, robot, visual), visual, progress=False)
    np.testing.assert_array_equal(again.visual, scores.visual)
    np.testing.assert_array_equal(again.total, scores.total)
    other = make_episodes(replace(SHORT, seed=1), robot, visual)
    assert not np.array_equal(other.visual["ee_pixel"], episodes.visual["ee_pixel"])


# ---- end to end -----------------------------------------------------------------------------------------
def test_short_benchmark_tells_self_from_a_second_arm_and_logs_one_mlflow_run(tmp_path, monkeypatch, pixel_model):
    torch.set_num_threads(1)
    monkeypatch.chdir(tmp_path)
    config = replace(SHORT, trials=40, steps=5, out=tmp_path / "out", mlflow=True, plots=True,
                     tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    paths = run_self_recognition(config, models=[pixel_model])
    for name in ("summary_md", "summary_csv", "episodes_csv", "roc", "auc_over_time", "scores", "free_energy"):
        assert paths[name].is_file() and paths[name].stat().st_size > 0
    rows = {r["comparison"]: r for r in csv.DictReader(paths["summary_csv"].open())}
    assert list(rows) == ["pooled", "second_arm", "delayed", "mirrored"]
    assert float(rows["second_arm"]["auc"]) > 0.9                    # self episodes score lower than the other arm
    episodes = list(csv.DictReader(paths["episodes_csv"].open()))
    self_scores = [float(e["score_visual"]) for e in episodes if e["kind"] == "self"]
    arm_scores = [float(e["score_visual"]) for e in episodes if e["kind"] == "second_arm"]
    assert np.median(self_scores) < np.median(arm_scores)
    assert "| pooled |" in paths["summary_md"].read_text()
    import mlflow
    runs = mlflow.search_runs(experiment_names=[config.experiment], output_format="list")
    assert len(runs) == 1
    assert runs[0].data.metrics["second_arm.auc"] == pytest.approx(float(rows["second_arm"]["auc"]))
    assert len(mlflow.artifacts.list_artifacts(run_id=runs[0].info.run_id)) == len(paths)
