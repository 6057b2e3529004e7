"""Rubber-hand benchmark: the drift grows with the visual precision (analytic models, per episode), synchronous
stroking drifts more than asynchronous, ownership evidence from stroke timing, and bad input refused before any
work (a lag beyond the episode, a seen hand out of the camera view, a model without a seen-hand modality)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bodyschema.evaluation.rubber_hand.benchmark import (
    RubberHandConfig,
    make_episodes,
    prepare,
    run_rubber_hand,
    track_drift,
)
from bodyschema.evaluation.rubber_hand.report import final_drift
from bodyschema.evaluation.rubber_hand.stroking import felt_strokes, ownership, strokes, temporal_log_lr
from bodyschema.models.analytic import AnalyticModel

SWEEP = RubberHandConfig(trials=3, displacements=(0.1, 0.2), visual_sigmas=(0.005, 0.01, 0.02, 0.05),
                         duration=8.0, final_window_s=2.0, visual_noise=False, mlflow=False, progress=False,
                         plots=False)


def drifts(config: RubberHandConfig):
    """(final drift (N,) m, episodes) of a run on the analytic planar2 models, without writing anything."""
    robot, sensors, visual = prepare(config, [AnalyticModel("planar2", "ee_xyz")])
    episodes = make_episodes(config, robot, visual)
    drift, failed = track_drift(config, robot, sensors, episodes)
    assert not failed.any()
    return final_drift(drift, episodes.times, config.final_window_s), drift, episodes


@pytest.fixture(scope="module")
def sweep():
    return drifts(SWEEP)


def test_drift_grows_with_the_visual_precision_in_every_episode(sweep):
    final, _, episodes = sweep
    conditions = SWEEP.conditions()
    for disp in SWEEP.displacements:
        for mode in ("synchronous", "asynchronous"):
            # (σ levels, trials): same trial = same pose, strokes and proprioceptive noise
            per_sigma = np.stack([final[episodes.condition == conditions.index((disp, s, mode))]
                                  for s in SWEEP.visual_sigmas])
            if mode == "synchronous":
                assert (np.diff(per_sigma, axis=0) < 0).all(), f"{disp} m {mode}: drift vs σ {per_sigma}"
            else:
                assert (np.diff(per_sigma, axis=0) <= 1e-6).all(), f"{disp} m {mode}: drift vs σ {per_sigma}"


def test_synchronous_stroking_drifts_more_than_asynchronous(sweep):
    final, drift, episodes = sweep
    conditions = SWEEP.conditions()
    for disp in SWEEP.displacements:
        for sigma in SWEEP.visual_sigmas:
            sync = final[episodes.condition == conditions.index((disp, sigma, "synchronous"))]
            late = final[episodes.condition == conditions.index((disp, sigma, "asynchronous"))]
            assert (sync > late).all(), (disp, sigma, sync, late)
    sharp = [i for i, c in enumerate(conditions) if c[2] == "synchronous" and c[1] == min(SWEEP.visual_sigmas)]
    sync = np.isin(episodes.condition, sharp)
    assert (final[sync] > 2 * drift[sync, 0]).all(), "under synchronous stroking the drift builds up over time"


def test_drift_is_a_fraction_of_the_displacement_and_grows_with_it(sweep):
    final, _, episodes = sweep
    conditions = SWEEP.conditions()
    for sigma in SWEEP.visual_sigmas:
        near, far = (final[episodes.condition == conditions.index((d, sigma, "synchronous"))]
                     for d in SWEEP.displacements)
        assert (far > near).all() and (far < max(SWEEP.displacements)).all()


def test_stroke_timing_is_evidence_of_ownership():
    rng = np.random.default_rng(0)
    felt = felt_strokes(rng, 10.0, 1.0, 0.1)
    assert 9 <= felt.size <= 11 and (np.diff(felt) > 0.7).all()
    sync = temporal_log_lr(*strokes(felt, "synchronous", 0.5), 0.2, 1.0)
    late = temporal_log_lr(*strokes(felt, "asynchronous", 0.5), 0.2, 1.0)
    assert (sync > 0).all() and (late < 0).all()
    times = np.arange(1, 41) * 0.25
    pairs = [strokes(felt, mode, 0.5) for mode in ("synchronous", "asynchronous", "vision_only")]
    own = ownership([f for f, _ in pairs], [s for _, s in pairs], np.array([0.1, 0.1, 0.1]), times, SWEEP)
    assert (np.diff(own[0]) >= 0).all() and (np.diff(own[1]) <= 0).all() and (np.diff(own[2]) == 0).all()
    assert own[0, -1] > 0.9 > own[2, -1] > SWEEP.prior_own > 0.01 > own[1, -1], "d = 10 cm: the seen hand is near"


def test_bad_input_is_refused_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="async_lag_s"):
        RubberHandConfig(duration=5.0, final_window_s=1.0, async_lag_s=6.0)
    with pytest.raises(ValueError, match="displacements"):
        RubberHandConfig(displacements=(0.0,))
    far = replace(SWEEP, robot="nao_arm", displacements=(0.3,), out=tmp_path / "view")
    with pytest.raises(ValueError, match="displacements.*camera view"):
        run_rubber_hand(far)
    assert not (tmp_path / "view").exists(), "no run folder before the input is checked"
    with pytest.raises(ValueError, match="model modalities"):
        run_rubber_hand(replace(SWEEP, out=tmp_path / "joints"), models=[AnalyticModel("planar2", "joints")])
    with pytest.raises(ValueError, match="robot 'planar2'"):
        run_rubber_hand(replace(SWEEP, out=tmp_path / "other"), models=[AnalyticModel("nao_arm", "ee_xyz")])
    assert not any(tmp_path.iterdir())


def test_a_short_run_writes_its_tables_and_plots(tmp_path):
    config = replace(SWEEP, trials=1, displacements=(0.1,), visual_sigmas=(0.01,), duration=4.0, plots=True,
                     out=tmp_path)
    paths = run_rubber_hand(config)
    assert {"conditions_csv", "over_time_csv", "episodes_csv", "summary", "drift_over_time_png",
            "drift_vs_precision_png", "models_csv"} <= set(paths)
    assert "Botvinick" in paths["summary"].read_text()


def test_a_pixel_view_of_the_seen_hand_drifts_as_its_position_does():
    """planar2's camera looks straight down at the arm's plane (constant depth): σ in m, converted to px at the seen
    hand, weighs the pixel view as the position view."""
    config = replace(SWEEP, displacements=(0.1,), visual_sigmas=(0.01,), modes=("synchronous",))
    xyz = drifts(config)[0]
    robot, sensors, visual = prepare(config, [AnalyticModel("planar2", "ee_pixel")])
    episodes = make_episodes(config, robot, visual)
    drift, failed = track_drift(config, robot, sensors, episodes)
    pixel = final_drift(drift, episodes.times, config.final_window_s)
    assert not failed.any() and np.allclose(pixel, xyz, rtol=0.02), (pixel, xyz)


def test_vision_alone_drifts_less_than_synchronous_stroking_and_more_than_asynchronous():
    config = replace(SWEEP, displacements=(0.1,), visual_sigmas=(0.01,), modes=("synchronous", "asynchronous",
                                                                              "vision_only"))
    final, _, episodes = drifts(config)
    sync, late, vision = (final[episodes.condition == c] for c in range(3))
    assert (late < vision).all() and (vision < sync).all(), (sync, late, vision)
