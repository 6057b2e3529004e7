"""The tracking benchmark on analytic models: what a run writes, the tracker against the same-budget flow, batched =
one stream at a time, lost-track runs, the timed model proxy and bad configs."""

from __future__ import annotations

import csv
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from bodyschema.aif.perception import Perception
from bodyschema.evaluation.tracking import TrackingConfig, run_tracking
from bodyschema.evaluation.tracking.benchmark import conditions, follow_all, sensed
from bodyschema.evaluation.tracking.methods import Clock, Timed, make_followers
from bodyschema.evaluation.tracking.report import lost_runs
from bodyschema.evaluation.tracking.streams import calibration_frames, make_streams
from tests.threads import one_thread

QUIET = dict(mlflow=False, progress=False)


@pytest.fixture(autouse=True)
def single_thread():
    with one_thread():
        yield


def test_a_run_writes_its_tables_and_plot_and_the_tracker_beats_the_same_budget_flow(tmp_path):
    config = TrackingConfig(trials=2, duration=1.0, rates=(10.0, 30.0), calibration_frames=20, out=tmp_path,
                            **QUIET)
    paths = run_tracking(config)
    assert {"summary_csv", "curves_csv", "summary_md", "error_vs_time", "models_csv"} <= set(paths)
    with open(paths["summary_csv"], newline="") as f:
        rows = list(csv.DictReader(f))
    cases = {(r["rate_hz"], r["condition"], r["method"]) for r in rows}
    assert len(cases) == len(rows) == 2 * (3 + 4), "rates × (ee_xyz: flow, tracker, +command; +joints: + reading)"
    assert "encoder" not in {r["method"] for r in rows}, "no encoder row without an encoder and an image model"
    assert {r["condition"] for r in rows if r["method"] == "reading"} == {"ee_xyz+joints"}
    fused = {(r["rate_hz"], r["method"]): float(r["joint_err_deg"]) for r in rows if r["condition"] == "ee_xyz+joints"}
    for rate in {r["rate_hz"] for r in rows}:
        assert fused[(rate, "tracker")] < fused[(rate, "flow")], fused
        assert fused[(rate, "tracker")] < fused[(rate, "reading")], "fusing 1 mm ee readings beats the 1° joints alone"
        assert abs(fused[(rate, "reading")] - 0.80) < 0.2, "the reading is as far off as its noise: E|N(0, 1°)| = 0.8°"
    assert all(float(r["evaluations_per_frame"]) <= 8 + 1e-9 for r in rows if r["method"] == "flow")
    assert "| case |" in paths["summary_md"].read_text()


def test_streams_followed_one_at_a_time_equal_the_batch():
    from bodyschema.evaluation.core.specs import load_robot, resolve_models
    models = resolve_models(("analytic:nao_arm:ee_xyz",), ())
    robot = load_robot(models)
    config = TrackingConfig(trials=3, duration=0.5, **QUIET)
    noise = dict(config.noise)
    name, used = conditions(config, models)[1]                              # ee_xyz + joints
    modalities = [m.modality for m in used]
    streams = make_streams(robot, modalities, 30.0, 3, 0.5, config.hold_s, noise, seed=0, key=0)
    calibration = calibration_frames(robot, modalities, 10, noise, seed=0)
    clock = Clock()
    timed, precisions = sensed(used, noise, clock)
    follower = make_followers(("tracker",), timed, config.tracker, None, precisions, calibration, 0)["tracker"]
    batch = follow_all(follower, streams, clock, batched=True)
    alone = follow_all(follower, streams, clock, batched=False)
    np.testing.assert_allclose(alone.mu, batch.mu, atol=1e-9, rtol=0)
    assert alone.ms.shape == (3 * (streams.q.shape[1] - 1),) and (alone.network_ms <= alone.ms).all()


def test_the_same_seed_draws_the_same_streams_and_another_seed_others():
    from bodyschema.evaluation.core.specs import load_robot, resolve_models
    robot = load_robot(resolve_models(("analytic:nao_arm:ee_xyz",), ()))
    a, b, c = (make_streams(robot, ["ee_xyz"], 30.0, 2, 0.5, (0.2, 1.0), {"ee_xyz": 0.001}, seed, key=0)
               for seed in (0, 0, 1))
    assert np.array_equal(a.q, b.q) and np.array_equal(a.observations["ee_xyz"], b.observations["ee_xyz"])
    assert not np.array_equal(a.q, c.q)
    assert math.isclose(1 / a.period, 30.0, rel_tol=0.05), "the rate is realised as whole physics steps"


def test_lost_runs_are_the_runs_of_off_track_frames():
    off = np.array([[0, 1, 1, 0, 0, 1], [0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0]], bool)
    assert lost_runs(off) == [(0, 2, True), (0, 1, False), (2, 1, True)]


def test_a_timed_model_is_still_a_sensory_model_and_its_calls_are_clocked():
    from bodyschema.models.analytic import AnalyticModel
    clock = Clock()
    model = Timed(AnalyticModel("nao_arm", "ee_xyz"), clock)
    q = torch.zeros(2, 4, dtype=torch.float64)
    result = Perception([model]).infer({"ee_xyz": model.predict(q)}, q + 0.05)
    assert result.mu.shape == (2, 4) and clock.ms > 0
    assert clock.lap() > 0 and clock.ms == 0.0


def test_a_learned_model_is_seen_through_its_noise_unless_its_precision_is_fixed():
    from bodyschema.evaluation.core.sensing import NoisySensor
    from tests.toy_models import ToyPlanarArm
    noisy, none = sensed([ToyPlanarArm()], {"ee_xyz": 0.01}, Clock())
    fixed, given = sensed([ToyPlanarArm()], {"ee_xyz": 0.01}, Clock(), {"ee_xyz": 5.0})
    assert isinstance(noisy[0]._model, NoisySensor) and none == {}
    assert isinstance(fixed[0]._model, ToyPlanarArm) and given == {"ee_xyz": 5.0}
    z = torch.zeros(1, 2, dtype=torch.float64)
    torch.testing.assert_close(noisy[0].precision(z), torch.full((1, 3), 1 / (1e-4 + 1e-4), dtype=torch.float64))


def test_the_noise_and_clock_wrappers_pass_a_networks_fused_calls_on_and_clock_them():
    """Free energy asks for predict_and_jacobian with hasattr: a wrapper that hid it made every Gauss–Newton step of
    the benchmark run two forwards. Through both wrappers the fused call gives the model's own values, clocked; a
    model without it stays without it."""
    from tests.models.test_pixel import blob_images, joint_angles, tiny_decoder
    from tests.toy_models import ToyPlanarArm
    q = joint_angles(16, seed=0)
    decoder = tiny_decoder(epochs=1).fit(q, blob_images(q), progress=False)
    clock = Clock()
    (seen,), _ = sensed([decoder], {"image": 0.02}, clock)
    prediction, jacobian = seen.predict_and_jacobian(q[:3])
    expected = decoder.predict_and_jacobian(q[:3])
    torch.testing.assert_close(prediction, expected[0], rtol=0, atol=0)
    torch.testing.assert_close(jacobian, expected[1], rtol=0, atol=0)
    assert clock.lap() > 0
    _, vjp = seen.predict_and_vjp(q[:3])
    assert clock.lap() > 0
    v = torch.ones(3, *decoder.output_shape)
    torch.testing.assert_close(vjp(v), decoder.vjp(q[:3], v))
    assert clock.lap() > 0, "the VJP function a fused call returns runs the backward: its time is the model's"
    (arm,), _ = sensed([ToyPlanarArm()], {"ee_xyz": 0.01}, clock)                 # a NoisySensor in a Timed
    assert not hasattr(arm, "predict_and_jacobian") and not hasattr(arm, "predict_and_vjp")


@pytest.mark.parametrize("change, message", [
    (dict(rates=()), "rates must be"), (dict(methods=("tracker", "kalman")), "methods must be"),
    (dict(noise=(("touch", 0.1),)), "noise must be"), (dict(fuse_joints=(True, True)), "fuse_joints must be"),
    (dict(duration=600.0, rates=(60.0,)), r"frames \(duration × rate\) must be"),
    (dict(hold_s=(0.5, 0.2)), "hold_s must be"), (dict(precisions=(("touch", 1.0),)), "precisions must be")])
def test_bad_configs_raise(change, message):
    with pytest.raises(ValueError, match=message):
        replace(TrackingConfig(), **change)
