"""Self-recognition benchmark: AUC and ROC (scikit-learn) on a hand-checked case, the streams of each source, the
AUC falling as the imitator's delay shrinks to 0, failures per episode, bad input, determinism, and a short
benchmark end to end where the robot tells its own body from a second arm and from a late imitator."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
import torch

from bodyschema.aif.perception import Perception
from bodyschema.evaluation.core.sensing import NoisySensor, sense
from bodyschema.evaluation.self_recognition.benchmark import (
    SelfRecognitionConfig,
    _free_energy,
    prepare,
    run_self_recognition,
    score_episodes,
)
from bodyschema.evaluation.self_recognition.report import (
    auc,
    balanced_accuracy,
    best_threshold,
    roc_curve,
    roc_table,
    time_to,
)
from bodyschema.evaluation.self_recognition.sensors import visual_only
from bodyschema.evaluation.self_recognition.streams import episode_conditions, imitate, make_episodes, mirror
from bodyschema.models.analytic import AnalyticModel
from tests.threads import one_thread

SHORT = SelfRecognitionConfig(trials=8, steps=4, delays=(0.0, 0.1), sources=("imitator", "second_arm", "mirrored"),
                              mlflow=False, progress=False, plots=False)


@pytest.fixture
def single_thread():
    with one_thread():
        yield


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


def test_auc_roc_and_youden_threshold_on_a_hand_checked_case():
    # self F = 1, 2, 3; other F = 2, 4. Pairs (self, other) with other > self: (1,2) (1,4) (2,4) (3,4), one tie
    # (2,2), one below (3,2): AUC = (4 + ½) / 6. "me" = F ≤ th: th = 1 → TPR ⅓ FPR 0; 2 → ⅔, ½; 3 → 1, ½; 4 → 1, 1.
    s, o = np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0])
    assert auc(s, o) == pytest.approx(0.75)
    roc = roc_curve(s, o)
    np.testing.assert_allclose(roc["threshold"], [-np.inf, 1, 2, 3, 4])
    np.testing.assert_allclose(roc["tpr"], [0, 1 / 3, 2 / 3, 1, 1])
    np.testing.assert_allclose(roc["fpr"], [0, 0, 0.5, 0.5, 1])
    assert best_threshold(roc) == {"threshold": 3.0, "tpr": 1.0, "fpr": 0.5}          # J = ½ beats ⅓
    assert balanced_accuracy(s, o) == pytest.approx(0.75)
    assert np.isnan(auc(s, [])) and np.isnan(best_threshold(roc_curve([], o))["threshold"])


def test_time_to_a_level_is_the_viewing_time_from_which_the_curve_stays_above_it():
    assert time_to(np.array([0.5, 0.96, 0.9, 0.97, 0.99]), 0.1) == pytest.approx(0.4)   # frame 4 of 5: 0.4 s
    assert time_to(np.array([0.96, 0.97]), 0.1) == pytest.approx(0.1)
    assert np.isnan(time_to(np.array([0.99, 0.9]), 0.1))


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
    kind = "learned"
    exact = False                                                     # stands for any non-exact model


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


def test_an_image_model_is_perceived_by_adam_then_lm_and_kinematics_by_the_flow_as_in_the_levels():
    from tests.aif.toys import ToyBlobImage, ToyJoints
    from tests.toy_models import ToyPlanarArm

    def method(config, models):                                  # the update the benchmark's Perception runs
        return Perception(models, config.perception).config.method

    assert method(SHORT, [ToyJoints(), ToyBlobImage()]) == "adam+lm"
    assert method(SHORT, [ToyJoints(), ToyPlanarArm()]) == "flow"
    lm = replace(SHORT, perception=replace(SHORT.perception, method="lm"))
    assert method(lm, [ToyJoints(), ToyBlobImage()]) == "lm"


def test_the_vision_alone_hypothesis_keeps_the_visual_models_and_their_precisions(setup):
    _, perception, _ = setup
    alone = visual_only(perception)
    assert [m.modality for m in alone.models] == ["ee_pixel"]
    assert alone.precisions == {"ee_pixel": perception.precisions["ee_pixel"]}
    torch.testing.assert_close((alone.low, alone.high), (perception.low, perception.high))


def test_one_body_explains_my_own_stream_at_little_cost_and_another_arms_at_a_high_one(short_run):
    episodes, scores = short_run
    cost = scores.score("contingency")                                # F(one body) − F(two bodies)
    mine, arm = cost[episodes.kind == "self"], cost[episodes.kind == "second_arm"]
    assert np.median(mine) < 3.0 < np.median(arm)                     # ½ εᵀΠε of noisy readings vs another pose
    np.testing.assert_allclose(scores.per_frame("contingency"), scores.total - scores.apart)


# ---- the streams ----------------------------------------------------------------------------------------
def test_every_condition_gets_the_trials_and_self_episodes_come_first():
    kinds, names, lags = episode_conditions(5, ("imitator", "second_arm"), [0, 2, 6], 0.05)
    assert kinds[:5].tolist() == ["self"] * 5 and len(kinds) == 5 * (1 + 3 + 1)
    assert list(dict.fromkeys(names)) == ["self", "imitator_0.00s", "imitator_0.10s", "imitator_0.30s", "second_arm"]
    assert lags[kinds == "imitator"].tolist() == [0] * 5 + [2] * 5 + [6] * 5 and not lags[kinds != "imitator"].any()


def test_the_imitator_scales_about_the_centre_adds_motor_noise_and_stays_in_the_box(setup):
    robot = setup[0]
    low, high = robot.sampling_ranges.T
    late = np.random.default_rng(0).uniform(low, high, size=(400, robot.dq))
    centre = (low + high) / 2
    exact = imitate(late, replace(SHORT, imitation_gain=0.5, imitation_noise=0.0), robot, np.random.default_rng(1))
    np.testing.assert_allclose(exact - centre, 0.5 * (late - centre))
    noisy = imitate(late, replace(SHORT, imitation_gain=1.0, imitation_noise=0.01), robot, np.random.default_rng(1))
    inside = ((late > low + 0.05) & (late < high - 0.05)).all(axis=1)            # away from the clipping
    assert np.std(noisy[inside] - late[inside]) == pytest.approx(0.01, rel=0.1)
    assert ((noisy >= low) & (noisy <= high)).all()


def test_mirrored_views_are_reflections_that_agree_between_3d_and_pixels(setup):
    robot = setup[0]
    q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(16, robot.dq))
    for modality in ("ee_pixel", "ee_xyz"):
        x = sense(robot, modality, q)
        np.testing.assert_allclose(mirror(robot, modality, mirror(robot, modality, x)), x, atol=1e-12)
        assert not np.allclose(mirror(robot, modality, x), x)
    np.testing.assert_allclose(robot.project(mirror(robot, "ee_xyz", sense(robot, "ee_xyz", q))),
                               mirror(robot, "ee_pixel", sense(robot, "ee_pixel", q)), atol=1e-9)


def test_streams_show_own_body_an_exact_late_copy_or_another_arm(setup):
    robot, _, visual = setup
    config = replace(SHORT, steps=8, proprio_noise=0.0, visual_noise=(), imitation_gain=1.0, imitation_noise=0.0)
    episodes = make_episodes(config, robot, visual)
    seen = episodes.visual["ee_pixel"]                                # (N, T, 2) px, noise-free
    mine = sense(robot, "ee_pixel", episodes.q.reshape(-1, robot.dq)).reshape(seen.shape)
    kind, name = episodes.kind, episodes.condition
    np.testing.assert_allclose(seen[kind == "self"], mine[kind == "self"], atol=1e-4)
    np.testing.assert_allclose(seen[name == "imitator_0.00s"], mine[name == "imitator_0.00s"], atol=1e-4)
    lag = round(0.1 / episodes.period)
    late = name == "imitator_0.10s"
    np.testing.assert_allclose(seen[late][:, lag:], mine[late][:, :-lag], atol=1e-4)
    np.testing.assert_allclose(episodes.delay[late], 0.1) and np.isnan(episodes.delay[kind == "self"]).all()
    assert not np.allclose(seen[kind == "second_arm"], mine[kind == "second_arm"], atol=1.0)
    np.testing.assert_array_equal(episodes.proprio, episodes.q)
    low, high = robot.sampling_ranges.T
    assert ((episodes.q >= low) & (episodes.q <= high)).all()


@pytest.mark.parametrize("seed", [0, 1])
def test_auc_falls_as_the_imitators_delay_shrinks_to_zero(pixel_model, seed):
    # An exact copy (gain 1, no motor noise) seen through noisy vision over a short window: at delay 0 its stream is
    # distributed as my own (AUC ≈ ½); every frame of delay makes it less contingent on my joints.
    config = replace(SHORT, trials=40, steps=10, sources=("imitator",), delays=(0.0, 0.05, 0.2, 0.4), seed=seed,
                     imitation_gain=1.0, imitation_noise=0.0, visual_noise=(("ee_pixel", 8.0),))
    robot, perception, visual = prepare(config, [pixel_model])
    episodes = make_episodes(config, robot, visual)
    scores = score_episodes(perception, episodes, visual, progress=False)
    rows, _, _ = roc_table(episodes.kind, episodes.condition, episodes.delay, scores.per_frame(), scores.failed,
                           episodes.period)
    aucs = [r["auc"] for r in rows[1:]]                              # by increasing delay
    assert [r["delay_s"] for r in rows[1:]] == pytest.approx([0.0, 0.05, 0.2, 0.4])
    assert abs(aucs[0] - 0.5) < 0.15
    assert all(a < b for a, b in zip(aucs, aucs[1:])), aucs


def test_image_streams_are_rendered_frames_scaled_as_training_data_and_flipped_in_the_mirror():
    from bodyschema.datagen.body.robot import Robot
    from bodyschema.models.scaling import IMAGE_SCALE
    robot = Robot.load("nao_arm", image_size=(14, 20))
    config = replace(SHORT, trials=3, steps=2, visual_noise=(), sources=("mirrored",))
    episodes = make_episodes(config, robot, ["image"])
    frames = robot.render(episodes.q.reshape(-1, robot.dq)).reshape(6, 2, 14, 20) / IMAGE_SCALE
    mirrored = episodes.kind == "mirrored"
    np.testing.assert_allclose(episodes.visual["image"][~mirrored], frames[~mirrored], atol=1e-6)
    np.testing.assert_allclose(episodes.visual["image"][mirrored], frames[mirrored][..., ::-1], atol=1e-6)
    robot.close()


@pytest.mark.usefixtures("single_thread")
def test_an_image_model_runs_the_benchmark_on_frames_from_its_own_camera(tmp_path, pixel_model):
    from bodyschema.datagen.body.robot import Robot
    from bodyschema.models.pixel import PixelDecoder
    robot = Robot.load("nao_arm", image_size=(14, 20))
    q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(32, robot.dq))
    decoder = PixelDecoder(pixel_model.body, "image", (14, 20), fc_hidden=8, channels=(4,), epochs=2, batch_size=32)
    decoder.fit(q, robot.render(q) / 255.0, progress=False)
    robot.close()
    paths = run_self_recognition(replace(SHORT, trials=2, steps=3, out=tmp_path), models=[decoder])
    episodes = list(csv.DictReader(paths["episodes_csv"].open()))
    assert len(episodes) == 2 * 5 and not any(e["failed"] == "True" for e in episodes)
    assert all(np.isfinite(float(e["score_visual"])) for e in episodes)


# ---- an image decoder on a fast arm ---------------------------------------------------------------------
ARM_IMAGE = (12, 16)


def arm_images(q: torch.Tensor, width_px: float = 0.8, points: int = 12) -> torch.Tensor:
    """A camera over the toy planar arm drawing both links (Gaussian lines): as with a rendered arm, an image F far
    from the true pose has minima of its own. q (N, 2) rad → (N, 12, 16) in [0, 1]."""
    from tests.toy_models import LINKS_M
    h, w = ARM_IMAGE
    q = torch.as_tensor(q, dtype=torch.float64)
    a, b = q[:, 0], q[:, 0] + q[:, 1]
    s = torch.linspace(0.0, 1.0, points, dtype=torch.float64)[None, :, None]                  # (1, P, 1)
    elbow = LINKS_M[0] * torch.stack([a.cos(), a.sin()], -1)[:, None]                        # (N, 1, 2) m
    hand = LINKS_M[1] * torch.stack([b.cos(), b.sin()], -1)[:, None]
    xy = torch.cat([s * elbow, elbow + s * hand], 1)                                         # (N, 2P, 2) m
    row, col = (0.5 - xy[..., 1] / 1.2) * (h - 1), (0.5 + xy[..., 0] / 1.2) * (w - 1)        # (N, 2P) px
    rr, cc = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    d2 = (rr - row[..., None, None]) ** 2 + (cc - col[..., None, None]) ** 2                 # (N, 2P, H, W)
    return torch.exp(-d2 / (2 * width_px ** 2)).amax(1).float()


@pytest.fixture(scope="module")
def arm_decoder():
    """A small pixel decoder of arm_images, run in float64 (as tests/aif/test_descent.py builds one)."""
    from bodyschema.models.pixel import PixelDecoder
    from tests.models.test_pixel import one_thread
    from tests.toy_models import ToyPlanarArm
    q = (torch.rand(512, 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64) * 4 - 2).float()
    with one_thread():
        decoder = PixelDecoder(ToyPlanarArm().body, "image", ARM_IMAGE, fc_hidden=32, channels=(8, 4), epochs=60,
                               batch_size=32, lr=1e-2, patience=100).fit(q, arm_images(q), seed=0, progress=False)
    decoder.compute_dtype = torch.float64
    return decoder


def fast_arm_episodes(n: int, frames: int, jump: float):
    """n self episodes, then n of a second arm, of a toy arm whose joints each jump ±`jump` rad every frame (a
    babbling nao_arm moves up to ~25–30° in one 0.05 s frame; the toy's 12×16 image has wider basins, so it jumps
    further); joints read with 1° noise, images noise-free."""
    from bodyschema.evaluation.self_recognition.streams import Episodes

    def walk(seed):                                                   # (n, T, 2) rad
        rng = np.random.default_rng(seed)
        q = np.empty((n, frames, 2))
        q[:, 0] = rng.uniform(-1.5, 1.5, (n, 2))
        for f in range(1, frames):
            q[:, f] = np.clip(q[:, f - 1] + jump * rng.choice([-1.0, 1.0], (n, 2)), -1.8, 1.8)
        return q

    own = np.concatenate([walk(0)] * 2)
    seen = np.concatenate([own[:n], walk(1)])                         # my arm, then a second arm
    proprio = own + np.radians(1.0) * np.random.default_rng(2).standard_normal(own.shape)
    images = arm_images(torch.from_numpy(seen.reshape(-1, 2))).reshape(2 * n, frames, *ARM_IMAGE).numpy()
    kind = np.array(["self"] * n + ["second_arm"] * n)
    return Episodes(kind, kind, np.full(2 * n, np.nan), own, proprio, {"image": images}, 0.05)


def test_one_body_keeps_an_image_decoders_pose_however_far_the_arm_moved_since_the_last_frame(arm_decoder):
    # Each frame the one-body belief starts at the joint readings, inside the image F's basin of the felt pose. Started
    # at the last frame's belief (the former code) it starts 0.7 rad away and may settle in a minimum of the image F
    # that the joints cannot pull it out of: its own body's image F then stays 10-40× its floor (with the 56×80
    # nao_arm decoder self vs second arm fell to chance, pooled AUC 0.54).
    from tests.aif.toys import ToyJoints
    episodes = fast_arm_episodes(12, 8, jump=0.7)
    update = SelfRecognitionConfig().perception                  # the benchmark's: "auto", adam+lm for an image model
    perception = Perception([ToyJoints(1.0 / np.radians(1.0) ** 2), arm_decoder], update,
                            {"image": 1e4})                       # vision outweighs the joints, as 56×80 images do
    mine = episodes.kind == "self"
    images = torch.from_numpy(episodes.visual["image"][mine].reshape(-1, *ARM_IMAGE)).double()
    floor = _free_energy(perception.models[1:], perception.precisions, {"image": images},
                         torch.from_numpy(episodes.q[mine].reshape(-1, 2)))[1]["image"].reshape(mine.sum(), -1)
    scores = {start: score_episodes(perception, episodes, ["image"], progress=False, start=start)
              for start in ("reading", "previous")}
    held = scores["reading"]
    assert not held.failed.any()
    assert (held.visual[mine] <= 1.5 * floor).all(), (held.visual[mine] / floor).max()   # never off the pose
    cost = held.score()
    assert auc(cost[mine], cost[~mine]) == 1.0
    lost = scores["previous"].visual[mine] > 2.0 * floor              # the case is one that the warm start fails
    assert lost.any(axis=1).sum() >= 3, lost.any(axis=1).sum()


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


def test_a_model_of_another_robot_or_without_a_visual_modality_raises_the_house_error_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="model body must be robot 'nao_arm'.*Got 'planar2'"):
        run_self_recognition(replace(SHORT, out=tmp_path), models=[AnalyticModel("planar2", "ee_pixel")])
    with pytest.raises(ValueError, match="model modalities must be .*Got \\['joints'\\]"):
        run_self_recognition(replace(SHORT, out=tmp_path), models=[AnalyticModel("nao_arm", "joints")])
    assert not any(tmp_path.iterdir()), "no run folder before the inputs are checked"


@pytest.mark.parametrize("bad, field", [
    (dict(trials=1), "trials"), (dict(sources=("twin",)), "sources"), (dict(score="mean"), "score"),
    (dict(start="warm"), "start"),
    (dict(visual_noise=(("ee_pixel", -1.0),)), "visual_noise"),
    (dict(delays=(0.0, 0.2)), "delays"),                             # SHORT's episode: 4 × 0.05 s = 0.2 s
    (dict(steps=20, delays=(0.0, 1.0)), "delays"), (dict(delays=(-0.05,)), "delays"), (dict(delays=()), "delays"),
    (dict(delays=(0.1, 0.11)), "delays"),                            # one frame twice
    (dict(imitation_gain=0.0), "imitation_gain"), (dict(imitation_noise=float("nan")), "imitation_noise")])
def test_bad_config_raises_the_house_error(bad, field):
    with pytest.raises(ValueError, match=f"{field}.* must be .*Got"):
        replace(SHORT, **bad)


def test_delays_are_free_when_no_imitator_is_shown():
    assert replace(SHORT, sources=("second_arm",), delays=(9.0,)).delays == (9.0,)


def test_the_same_seed_reproduces_the_scores_exactly(setup, short_run):
    robot, perception, visual = setup
    episodes, scores = short_run
    again = score_episodes(perception, make_episodes(SHORT, robot, visual), visual, progress=False)
    np.testing.assert_array_equal(again.visual, scores.visual)
    np.testing.assert_array_equal(again.total, scores.total)
    other = make_episodes(replace(SHORT, seed=1), robot, visual)
    assert not np.array_equal(other.visual["ee_pixel"], episodes.visual["ee_pixel"])


# ---- end to end -----------------------------------------------------------------------------------------
@pytest.mark.usefixtures("single_thread")
def test_short_benchmark_tells_self_from_a_second_arm_and_a_late_imitator(tmp_path, monkeypatch, pixel_model):
    monkeypatch.chdir(tmp_path)
    config = replace(SHORT, trials=20, steps=10, delays=(0.0, 0.4), out=tmp_path / "out", mlflow=True, plots=True,
                     tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    paths = run_self_recognition(config, models=[pixel_model])
    for name in ("summary_md", "summary_csv", "viewing_time_csv", "episodes_csv", "roc", "viewing_time", "delay",
                 "scores", "free_energy"):
        assert paths[name].is_file() and paths[name].stat().st_size > 0
    rows = {r["comparison"]: r for r in csv.DictReader(paths["summary_csv"].open())}
    assert list(rows) == ["pooled", "imitator_0.00s", "imitator_0.40s", "second_arm", "mirrored"]
    viewing = [r for r in csv.DictReader(paths["viewing_time_csv"].open()) if r["comparison"] == "second_arm"]
    assert [float(r["viewing_s"]) for r in viewing] == pytest.approx(0.05 * np.arange(1, 11))
    assert float(viewing[-1]["auc"]) == pytest.approx(float(rows["second_arm"]["auc"]))   # the whole window
    assert float(rows["second_arm"]["auc"]) > 0.9 and float(rows["imitator_0.40s"]["auc"]) > 0.9
    assert float(rows["imitator_0.40s"]["auc"]) > float(rows["imitator_0.00s"]["auc"])
    assert float(rows["imitator_0.40s"]["t95_s"]) <= 10 * 0.05
    episodes = list(csv.DictReader(paths["episodes_csv"].open()))
    self_scores = [float(e["score_visual"]) for e in episodes if e["kind"] == "self"]
    arm_scores = [float(e["score_visual"]) for e in episodes if e["kind"] == "second_arm"]
    assert np.median(self_scores) < np.median(arm_scores)
    assert "| imitator_0.40s |" in paths["summary_md"].read_text()
    import mlflow
    runs = mlflow.search_runs(experiment_names=[config.experiment], output_format="list")
    assert len(runs) == 1
    assert runs[0].data.metrics["second_arm.auc"] == pytest.approx(float(rows["second_arm"]["auc"]))
    assert len(mlflow.artifacts.list_artifacts(run_id=runs[0].info.run_id)) == len(paths)
