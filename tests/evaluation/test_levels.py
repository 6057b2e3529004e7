"""Levels benchmark: held-out targets, initial beliefs, oracle sanity checks, mismatch errors, reports."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.specs import load_robot
from bodyschema.evaluation.levels.benchmark import (
    STATIC_DT,
    STATIC_PERCEPTION,
    LevelsConfig,
    broken_sweep,
    evaluate_level,
    noise_sweep,
    run_levels,
)
from bodyschema.evaluation.levels.report import plot_sweep
from bodyschema.evaluation.levels.targets import OFFSET_DEG, initial_beliefs, make_targets
from bodyschema.models import analytic
from tests.toy_models import ToyPlanarArm


@pytest.fixture(scope="module")
def planar2_xyz():
    return analytic.AnalyticModel("planar2", "ee_xyz")


@pytest.fixture(scope="module")
def planar2(planar2_xyz):
    return load_robot([planar2_xyz])


# ---- targets and beliefs --------------------------------------------------------------------------------
def test_targets_are_seeded_inside_the_ranges_and_held_out_from_datagen(planar2):
    a = make_targets(planar2, 20, eval_rng(0, 0, "targets"))
    b = make_targets(planar2, 20, eval_rng(0, 0, "targets"))
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.observations["ee_xyz"], b.observations["ee_xyz"])
    low, high = planar2.sampling_ranges.T
    assert ((a.q >= low) & (a.q <= high)).all()
    datagen_first = np.random.default_rng(np.random.SeedSequence([0, 0])).random((20, 2))
    assert not np.allclose(eval_rng(0, 0, "targets").random((20, 2)), datagen_first)
    assert not np.allclose(make_targets(planar2, 20, eval_rng(0, 1, "targets")).q, a.q), "runs differ"


@pytest.mark.parametrize("level", [1, 2])
def test_level_1_and_2_beliefs_are_off_by_5_to_10_degrees_inside_the_range(level):
    ranges = np.array([[-0.5, 0.5], [-1.0, 1.0], [-0.2, 0.3]])
    q = np.random.default_rng(0).uniform(ranges[:, 0], ranges[:, 1], size=(400, 3))
    mu0 = initial_beliefs(level, q, ranges, np.random.default_rng(1))
    off = np.rad2deg(np.abs(mu0 - q))
    assert ((mu0 >= ranges[:, 0]) & (mu0 <= ranges[:, 1])).all()
    moved = off > 1e-9
    assert (moved.sum(1) == (1 if level == 1 else 3)).all()
    assert ((off[moved] >= OFFSET_DEG[0] - 1e-9) & (off[moved] <= OFFSET_DEG[1] + 1e-9)).all()


def test_level_3_belief_is_another_targets_pose():
    q = np.random.default_rng(0).random((50, 2))
    mu0 = initial_beliefs(3, q, np.array([[0, 1], [0, 1]]), np.random.default_rng(1))
    assert not (mu0 == q).all(1).any()
    assert {tuple(r) for r in mu0} == {tuple(r) for r in q}


# ---- oracle sanity checks -------------------------------------------------------------------------------
@pytest.mark.parametrize("level", [1, 2])
def test_oracle_planar2_levels_1_2_converge_below_a_tenth_of_a_degree(planar2_xyz, planar2, level):
    targets = make_targets(planar2, 50, eval_rng(0, 0, "targets"))
    row, trial, result = evaluate_level(Perception([planar2_xyz]), planar2, targets, level,
                                        eval_rng(0, 0, "beliefs", level))
    # ee_xyz fixes both joints only locally: within 10° of the straight elbow the perturbed belief may cross
    # the singularity into the mirror (elbow-flipped) solution, which matches the observation as well.
    regular = np.abs(np.rad2deg(targets.q[:, 1])) > OFFSET_DEG[1] + 2
    assert regular.sum() > 40
    assert trial["mean_err_deg"][regular].max() < 0.1
    assert trial["ee_err_mm"].max() < 0.01, "every trial reaches the observed end effector"
    assert row["steps"] < 30 and result.converged.all()


def test_oracle_nao_arm_fusion_beats_every_sensor_alone():
    sigma = {"ee_xyz": 1e-3, "ee_pixel": 1.0, "joints": math.radians(2.0)}   # m, px, rad; as the precisions
    models = {m: analytic.AnalyticModel("nao_arm", m) for m in sigma}
    robot = load_robot(list(models.values()))
    targets = make_targets(robot, 50, eval_rng(0, 0, "targets"), noise=sigma, noise_rng=eval_rng(0, 0, "noise"))
    precisions = {m: s ** -2 for m, s in sigma.items()}

    def error(names):
        perception = Perception([models[n] for n in names], precisions={n: precisions[n] for n in names})
        return evaluate_level(perception, robot, targets, 2, eval_rng(0, 0, "beliefs", 2))[0]["joint_err_deg"]

    fused = error(list(sigma))
    alone = {n: error([n]) for n in sigma}
    assert all(fused < e for e in alone.values()), (fused, alone)


def test_oracle_ee_orientation_closes_what_ee_xyz_leaves_unseen():
    # Level 1 on the 4-joint nao_arm: three coordinates leave a 1-D null space of J, and the start's component in
    # it stays (~0.6°); the ee's pose (position and orientation) leaves none, so the belief must end at the truth.
    models = {m: analytic.AnalyticModel("nao_arm", m) for m in ("ee_xyz", "ee_rot")}
    robot = load_robot(list(models.values()))
    targets = make_targets(robot, 40, eval_rng(0, 0, "targets"))

    def level_1(names):
        perception = Perception([models[n] for n in names])
        return evaluate_level(perception, robot, targets, 1, eval_rng(0, 0, "beliefs", 1))[1]["mean_err_deg"]

    xyz, pose = level_1(["ee_xyz"]), level_1(["ee_xyz", "ee_rot"])
    assert xyz.mean() > 0.3, "ee_xyz alone leaves the null-space part of the start"
    assert np.median(pose) < 0.01 and pose.mean() < 0.1 * xyz.mean()


class SlightlyOffRotation(analytic.AnalyticModel):
    """The panda's exact ee_rot plus a smooth error of 5e-4 per entry (0.03°, as a GP fitted on 6 000 poses)."""

    def __init__(self):
        super().__init__("panda", "ee_rot")
        self.w = torch.from_numpy(np.random.default_rng(0).normal(size=(9, 7)))   # (9, Dz) rad⁻¹

    def _predict(self, z):
        return super()._predict(z) + 5e-4 * torch.sin(z @ self.w.T)

    def _jacobian(self, z):
        return super()._jacobian(z) + 5e-4 * torch.cos(z @ self.w.T)[:, :, None] * self.w


def test_the_static_step_holds_a_redundant_arm_where_its_readings_leave_it_open():
    # The 7-joint panda under its ee's pose keeps a 1-D self-motion no reading moves; the model's own small error
    # is all the gradient there. The levels' Δt must hold the belief (the exact model's 0.7°); the library's 1000
    # walks it along the self-motion.
    models = [analytic.AnalyticModel("panda", "ee_xyz"), SlightlyOffRotation()]
    robot = load_robot(models)
    targets = make_targets(robot, 30, eval_rng(0, 0, "targets"))

    def level_1(dt):
        config = replace(STATIC_PERCEPTION, flow=replace(STATIC_PERCEPTION.flow, dt=dt))
        return evaluate_level(Perception(models, config), robot, targets, 1, eval_rng(0, 0, "beliefs", 1))[0]

    held, walked = level_1(STATIC_DT), level_1(1000.0)
    assert held["joint_err_deg"] < 1.0 and held["ee_err_mm"] < 0.1
    assert walked["joint_err_deg"] > 2 * held["joint_err_deg"]


def test_model_of_another_robot_raises(planar2):
    with pytest.raises(ValueError, match="model body must be robot 'planar2'"):
        from bodyschema.evaluation.core.specs import check_models_match
        check_models_match([ToyPlanarArm()], planar2)
    with pytest.raises(ValueError, match="body must be robot"):
        run_levels(LevelsConfig(models=("analytic:planar2:ee_xyz", "analytic:nao_arm:joints"), trials=2, runs=1,
                                mlflow=False, plots=False))


def test_bad_config_and_spec_raise():
    with pytest.raises(ValueError, match="levels must be"):
        LevelsConfig(levels=(4,))
    with pytest.raises(ValueError, match="model spec must be"):
        run_levels(LevelsConfig(models=("no-such-model",), mlflow=False))


# ---- the benchmark end to end ---------------------------------------------------------------------------
def test_run_levels_writes_tables_plots_and_one_mlflow_run(tmp_path, monkeypatch, planar2_xyz):
    monkeypatch.chdir(tmp_path)
    config = LevelsConfig(trials=20, runs=2, out=tmp_path / "out", multistart=4, screen_steps=5,
                          tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    summary = run_levels(config, models=[planar2_xyz])
    assert [r["level"] for r in summary.table] == ["1", "2", "3", "3+ms"]
    assert len(summary.rows) == 2 * 4 and summary.per_trial["1"].shape == (40,)
    assert summary.table[0]["success"] > 0.9
    assert summary.table[3]["success"] >= summary.table[2]["success"] - 1e-9
    for name in ("runs_csv", "summary_csv", "summary_md", "boxplot", "free_energy"):
        assert summary.paths[name].is_file() and summary.paths[name].stat().st_size > 0
    assert "| 3+ms |" in summary.paths["summary_md"].read_text()
    import mlflow
    run = mlflow.get_run(summary.run_id)
    assert run.data.metrics["L1.success"] == pytest.approx(summary.table[0]["success"])
    assert len(mlflow.artifacts.list_artifacts(run_id=summary.run_id)) == len(summary.paths)


def test_noise_and_broken_sensor_sweeps(tmp_path, planar2_xyz):
    joints = analytic.AnalyticModel("planar2", "joints")
    config = LevelsConfig(trials=20, runs=1, out=tmp_path, mlflow=False,
                          perception=PerceptionConfig(precisions=(("joints", math.radians(1.0) ** -2),)))
    rows = noise_sweep(config, "joints", [0.0, math.radians(1.0), math.radians(5.0)], models=[planar2_xyz, joints])
    errors = [r["joint_err_deg"] for r in rows]
    assert errors[0] < errors[2]
    broken = broken_sweep(config, models=[planar2_xyz, joints])
    assert [r["broken"] for r in broken] == ["none", "ee_xyz", "joints"]
    assert broken[0]["joint_err_deg"] < 0.1 and broken[1]["joint_err_deg"] < 0.1, "one sensor left suffices"
    assert plot_sweep(rows, "sigma", tmp_path / "noise.png").stat().st_size > 0
    assert plot_sweep(broken, "broken", tmp_path / "broken.png").stat().st_size > 0


# ---- level 3 from an amortized encoder --------------------------------------------------------------------
def _encoder(robot_name: str, image_size, tmp_path):
    """A one-epoch image encoder of `robot_name` saved to tmp_path: enough to test the plumbing, not accuracy."""
    from bodyschema.datagen.body.robot import Robot
    from bodyschema.models.encoder import ImageEncoder
    from bodyschema.models.scaling import BodySpec
    robot = Robot.load(robot_name, image_size=image_size)
    q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(32, robot.dq))
    body = BodySpec(robot.name, robot.joint_names, *map(tuple, robot.sampling_ranges.T))
    encoder = ImageEncoder(body, "image", image_size, channels=(4, 8), fc_hidden=8, epochs=1)
    encoder.fit(q, robot.render(q), progress=False)
    encoder.save(tmp_path / robot_name)
    return f"trusted:{tmp_path / robot_name}"      # a local directory, loaded unchecked on purpose


def test_level3_runs_from_the_encoder_alone_and_as_a_multistart_seed(planar2_xyz, planar2, tmp_path):
    spec = _encoder("planar2", planar2.image_size, tmp_path)
    config = LevelsConfig(levels=(3,), trials=12, runs=1, multistart=3, screen_steps=2, encoder=spec,
                          mlflow=False, plots=False, out=tmp_path / "out")
    rows = run_levels(config, models=[planar2_xyz]).table
    assert [r["level"] for r in rows] == ["3", "3+ms", "3+enc", "3+enc+ms"]
    config = replace(config, levels=(1,), trials=4, multistart=0)
    assert [r["level"] for r in run_levels(config, models=[planar2_xyz]).table] == ["1", "1+enc"]


def test_levels_1_2_with_the_encoder_keep_the_lower_free_energy_of_both_starts(planar2_xyz, planar2, tmp_path):
    from bodyschema.models import load_model
    encoder = load_model(_encoder("planar2", planar2.image_size, tmp_path).removeprefix("trusted:"))
    perception = Perception([planar2_xyz], PerceptionConfig(flow=FlowSettings(step_control="descent")))
    targets = make_targets(planar2, 16, eval_rng(0, 0, "targets"), True, {}, eval_rng(0, 0, "noise"))
    for level in (1, 2):
        own = evaluate_level(perception, planar2, targets, level, eval_rng(0, 0, "beliefs", level))
        both = evaluate_level(perception, planar2, targets, level, eval_rng(0, 0, "beliefs", level), encoder=encoder)
        assert both[0]["level"] == f"{level}+enc"
        assert (both[2].F <= own[2].F + 1e-9 * own[2].F.abs()).all()


def test_encoder_of_another_robot_is_refused_before_any_work(planar2_xyz, tmp_path):
    spec = _encoder("nao_arm", (56, 80), tmp_path)
    config = LevelsConfig(levels=(3,), trials=4, runs=1, encoder=spec, mlflow=False, plots=False, out=tmp_path / "o")
    with pytest.raises(ValueError, match="model body must be robot 'planar2'"):
        run_levels(config, models=[planar2_xyz])
    assert not (tmp_path / "o").exists()


def test_cuda_without_cuda_is_the_house_error(planar2_xyz, tmp_path):
    import torch
    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    config = LevelsConfig(levels=(1,), trials=4, runs=1, device="cuda", mlflow=False, plots=False, out=tmp_path)
    with pytest.raises(ValueError, match="device must be"):
        run_levels(config, models=[planar2_xyz])


def test_each_start_is_inferred_once_per_run_and_the_encoder_rows_count_the_work_of_both(planar2_xyz, planar2,
                                                                                       tmp_path, monkeypatch):
    from bodyschema.evaluation.levels import benchmark
    spec = _encoder("planar2", planar2.image_size, tmp_path)
    calls, infer = [], Perception.infer

    def counted(self, obs, mu0, goal=None):
        calls.append(len(mu0))
        return infer(self, obs, mu0, goal)

    monkeypatch.setattr(Perception, "infer", counted)
    config = LevelsConfig(trials=6, runs=2, multistart=0, encoder=spec, mlflow=False, plots=False, out=tmp_path / "o",
                          floor=False)                                     # the floor's own start: test_levels_floor
    summary, _ = benchmark.measure_levels(config, [planar2_xyz])
    assert len(calls) == 2 * 4, "per run: levels 1, 2, 3 and the encoder's guess, each once"
    for run in (0, 1):
        row = {r["level"]: r for r in summary.rows if r["run"] == run}
        for level in (1, 2):
            assert row[f"{level}+enc"]["evaluations_per_trial"] == pytest.approx(
                row[str(level)]["evaluations_per_trial"] + row["3+enc"]["evaluations_per_trial"])

