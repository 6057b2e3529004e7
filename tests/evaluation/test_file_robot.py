"""Everything downstream works on a robot from a file (issue 20, item 6), on a tiny 3-hinge MJCF arm written here with
its record beside it: `analytic:<file>:<modality>` specs, datagen (uniform and babble, with images), training gpr, mdn
and pixel on its store, the levels (trained models and the oracle), reaching, self-recognition and the report.
A model's body carries its robot (record and model text) unless the robot is shipped, so the robot is found the same
way everywhere and a model still evaluates when the file has moved; shipped robots' bodies are saved as before."""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from bodyschema.datagen.body.attrs import robot_attrs
from bodyschema.datagen.body.record import dumps_toml
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.schema import open_store
from bodyschema.datagen.store.validate import validate_store
from bodyschema.evaluation.core.specs import load_robot, resolve_model
from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels, run_levels
from bodyschema.models import load_model
from bodyschema.models.analytic import AnalyticModel
from bodyschema.models.body_robot import attrs_source, body_robot, robot_source
from tests.test_cli_fuzz import run_and_check
from tests.threads import one_thread

ARM = """<mujoco model="arm3"><compiler angle="radian"/><worldbody><light pos="0 0 2" dir="0 0 -1"/>
  <body name="base" pos="0 0 0.05"><joint name="yaw" axis="0 0 1" range="-1.5 1.5"/>
    <geom type="cylinder" size="0.04 0.03" mass="0.5"/>
    <body name="upper" pos="0 0 0.04"><joint name="shoulder" axis="0 1 0" range="-1.2 1.2"/>
      <geom type="capsule" fromto="0 0 0 0 0 {upper}" size="0.02" mass="0.3"/>
      <body name="lower" pos="0 0 {upper}"><joint name="elbow" axis="0 1 0" range="-1.8 1.8"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.2" size="0.018" mass="0.2"/><site name="ee" pos="0 0 0.2"/>
  </body></body></body></worldbody></mujoco>"""
BOX = [[-1.5, 1.5], [-1.2, 1.2], [-1.8, 1.8]]
RECORD = {"name": "arm3", "model": "arm3.xml", "image_size": [16, 16], "joints": ["yaw", "shoulder", "elbow"],
          "ee": {"site": "ee"}, "workspaces": {"full": BOX, "camera": BOX},
          "camera": {"name": "auto", "pos": [0.287, -1.182, 0.685], "fovy": 45.0,
                     "xyaxes": [0.970475, 0.240077, 0.023256, -0.099991, 0.3127, 0.944574]},
          "actuators": {"kind": "servos", "kp": [10.2, 18.7, 3.9], "kv": [1.0, 1.5, 0.2]}}
FAST = {"mlflow": False, "progress": False}


def write_arm(folder: Path, upper: float = 0.25, name: str = "arm3") -> Path:
    """arm3.xml and its record (as `bodyschema robot init` would write it, edited) in `folder`; → the MJCF."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "arm3.xml").write_text(ARM.format(upper=upper))
    (folder / "arm3.toml").write_text(dumps_toml({**RECORD, "name": name}))
    return folder / "arm3.xml"


@pytest.fixture(scope="module")
def arm(tmp_path_factory) -> Path:
    return write_arm(tmp_path_factory.mktemp("arm"))


@pytest.fixture(scope="module")
def stores(arm) -> dict[str, Path]:
    """Uniform poses and babbling episodes of the arm, both with 16 × 16 images."""
    folder = arm.parent
    return {"uniform": generate(DatagenConfig(robot=str(arm), n=64, out=folder / "uniform.zarr"), progress=False),
            "babble": generate(DatagenConfig(robot=str(arm), n=64, sampler="babble", episode_s=1.6,
                                             out=folder / "babble.zarr"), progress=False)}


@pytest.fixture(scope="module")
def trained(stores, tmp_path_factory) -> dict:
    """gpr (ee_xyz) and mdn (ee_pixel) on the uniform store, pixel (image) on the babbling one, tiny, registered in
    a fresh MLflow store: {kind: registry spec, "uri": its tracking URI}."""
    from bodyschema.models.configs import GPRConfig, MDNConfig, PixelConfig
    from bodyschema.training.config import TrainConfig
    from bodyschema.training.train import train

    folder = tmp_path_factory.mktemp("train")
    uri = f"sqlite:///{folder / 'mlflow.db'}"
    jobs = {"gpr": (GPRConfig(hyper_points=40, max_points=60, adam_steps=5, lbfgs_steps=10), "uniform", "ee_xyz"),
            "mdn": (MDNConfig(hidden=(16,), epochs=5), "uniform", "ee_pixel"),
            "pixel": (PixelConfig(fc_hidden=16, channels=(8, 4), epochs=3), "babble", "image")}
    out = {"uri": uri}
    with one_thread():
        for kind, (hyper, store, modality) in jobs.items():
            result = train(TrainConfig(model=hyper, data=stores[store], modality=modality, tracking_uri=uri,
                                       run_root=folder / "runs", progress=False))
            out[kind] = f"models:/{result.registered_name}/{result.model_version}"
    return out


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


# ---- the body carries the robot ---------------------------------------------------------------------------
def test_an_analytic_spec_of_a_file_is_its_record_robot_and_evaluates_after_the_file_moved(tmp_path):
    """Before: the body was named after the spec string (the path), the robot after its record: the levels could
    not load it. Now: named after the record, with the model text, so a saved model needs no file."""
    spec_file = write_arm(tmp_path / "mine")
    model = resolve_model(f"analytic:{spec_file}:ee_xyz")
    assert model.body.robot == "arm3" and model.body.source["robot_model"]["sha256"] == _sha256(spec_file)
    model.save(tmp_path / "saved")
    z = torch.from_numpy(np.array([[0.3, -0.4, 0.9]]))
    expected = model.predict(z)
    shutil.rmtree(tmp_path / "mine")                                   # the file and its record are gone
    loaded = load_model(tmp_path / "saved")
    torch.testing.assert_close(loaded.predict(z), expected)
    summary, _ = measure_levels(LevelsConfig(trials=3, runs=1, levels=(1,), multistart=0, **FAST), [loaded])
    assert summary.table[0]["joint_err_deg"] < 0.1                     # the exact oracle from level 1's close start


def test_the_jaco_mjcf_with_meshes_saves_its_mesh_digests_and_scores_its_levels(tmp_path):
    """dm_control's Kinova Jaco (STL meshes), when the test extra is installed: the body keeps the meshes' digests
    (checked when the robot is rebuilt) and the levels run on the saved oracle."""
    import importlib.metadata

    try:
        jaco = importlib.metadata.distribution("dm_control").locate_file("dm_control/third_party/kinova/jaco_arm.xml")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("dm_control is not installed (pip install -e '.[test]')")
    model = resolve_model(f"analytic:{jaco}:ee_pixel")
    assert model.body.robot == "jaco_arm" and "arm.stl" in model.body.source["robot_model"]["meshes"]
    model.save(tmp_path / "saved")
    models = [load_model(tmp_path / "saved"), resolve_model(f"analytic:{jaco}:joints")]
    summary, _ = measure_levels(LevelsConfig(trials=3, runs=1, levels=(1,), multistart=0, **FAST), models)
    assert summary.table[0]["joint_err_deg"] < 0.1


def test_shipped_robots_are_found_by_name_and_saved_as_before(arm):
    model = AnalyticModel("planar2", "ee_xyz")
    assert model.body.source is None and "source" not in model.body.to_dict()
    assert attrs_source({"robot": "planar2", **robot_attrs(Robot.load("planar2"))}) is None
    with Robot.load(arm) as file_robot:
        assert robot_source(file_robot) is not None, "a file robot carries its model's source"
    with pytest.raises(ValueError, match="must be not a shipped robot's name"):   # its stores would fail validate
        Robot.load(write_arm(arm.parent / "named_planar2", name="planar2"))


def test_datagen_uniform_and_babble_with_images_on_the_file_robot(stores, arm):
    for name, path in stores.items():
        assert validate_store(path) == [], name
        root = open_store(path)
        attrs = dict(root.attrs)
        assert attrs["robot"] == "arm3" and root["image"].shape == (64, 16, 16), name
        assert attrs_source(attrs)["robot_model"]["sha256"] == _sha256(arm)
    assert len(np.unique(open_store(stores["babble"])["episode"][:])) == 2


def test_gpr_mdn_and_pixel_trained_on_its_store_carry_the_stores_robot(trained, stores, arm):
    source = attrs_source(dict(open_store(stores["uniform"]).attrs))
    for kind in ("gpr", "mdn", "pixel"):
        model = resolve_model(trained[kind], trained["uri"])
        assert model.body.robot == "arm3" and model.body.source == source, kind
        with body_robot(model.body) as robot:
            assert robot.mjcf_sha256 == _sha256(arm) and robot.joint_names == ("yaw", "shoulder", "elbow")


# ---- the benchmarks ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs(trained, arm, tmp_path_factory) -> dict:
    """Levels (a trained model fused with the analytic oracle; the pixel decoder), reaching and self-recognition on
    the file robot with its trained models, all in one results folder: {name: summary or paths, "results": folder}."""
    from bodyschema.evaluation.reaching.benchmark import ReachingConfig, run_reaching
    from bodyschema.evaluation.self_recognition.benchmark import SelfRecognitionConfig, run_self_recognition

    results, uri = tmp_path_factory.mktemp("results"), trained["uri"]
    levels = LevelsConfig(trials=3, runs=1, levels=(1, 2), multistart=0, tracking_uri=uri, plots=False,
                          out=results / "levels", perception=replace(LevelsConfig().perception, max_steps=30), **FAST)
    reaching = ReachingConfig(robot=str(arm), models=(trained["gpr"], f"analytic:{arm}:joints"), trials=2,
                              duration=0.4, goal_starts=2, tracking_uri=uri, out=results / "reaching", **FAST)
    sr = SelfRecognitionConfig(robot=str(arm), models=(trained["mdn"],), trials=2, steps=4, delays=(0.0,),
                               tracking_uri=uri, plots=False, out=results / "self_recognition", **FAST)
    with one_thread():
        return {"fused": run_levels(replace(levels, models=(trained["gpr"], f"analytic:{arm}:ee_pixel"))),
                "pixel": run_levels(replace(levels, models=(trained["pixel"],))),
                "reaching": run_reaching(reaching), "self_recognition": run_self_recognition(sr), "results": results}


def test_levels_with_trained_models_and_the_analytic_oracle(runs, trained):
    for name in ("fused", "pixel"):
        table = runs[name].table
        assert [r["level"] for r in table] == ["1", "2"], name
        assert all(np.isfinite(r["joint_err_deg"]) and np.isfinite(r["ee_err_mm"]) for r in table), name
    assert trained["pixel"] in runs["pixel"].paths["models_csv"].read_text()


def test_reaching_on_the_file_robot_with_a_trained_model(runs):
    text = runs["reaching"]["summary_md"].read_text()
    assert text.count("| aif |") == 1 and text.count("| pd |") == 1 and "Reaching on arm3:" in text


def test_self_recognition_on_the_file_robot_with_a_trained_model(runs, trained):
    paths = runs["self_recognition"]
    assert "Self-recognition on arm3" in paths["summary_md"].read_text()
    assert trained["mdn"] in paths["models_csv"].read_text()


def test_the_report_gathers_the_file_robots_runs(runs, trained):
    from bodyschema.evaluation.report.page import ReportConfig, write_report

    page = write_report(ReportConfig(results=runs["results"]))["markdown"].read_text()
    assert "Reaching on arm3:" in page and "Self-recognition on arm3" in page and trained["pixel"] in page


def test_levels_on_the_recorded_frames_of_its_store_score_the_ee_by_its_robot(stores, arm):
    """Before: the store's robot was looked up by name, which a file robot has not: the ee error was NaN."""
    config = LevelsConfig(trials=4, runs=1, levels=(1,), multistart=0, targets=stores["uniform"], **FAST)
    summary, _ = measure_levels(config, [resolve_model(f"analytic:{arm}:ee_xyz")])
    assert summary.table[0]["ee_err_mm"] < 0.1 and summary.targets["robot"] == "arm3"


def test_two_arms_of_one_name_are_not_one_body(arm, tmp_path):
    other = write_arm(tmp_path / "longer", upper=0.3)
    models = [resolve_model(f"analytic:{arm}:ee_xyz"), resolve_model(f"analytic:{other}:ee_pixel")]
    with pytest.raises(ValueError, match=r"ee_pixel model's robot file must be the benchmark robot's"):
        load_robot(models)


# ---- bad input at the CLI, beside tests/test_cli_fuzz.py ----------------------------------------------------
CASES = [
    ("levels-analytic-missing-file", "evaluate levels --model analytic:{W}/nothere.xml:ee_xyz --out {W}/res"),
    ("levels-analytic-not-a-model", "evaluate levels --model analytic:{W}/arm.sdf:ee_xyz --out {W}/res"),
    ("levels-analytic-bad-modality", "evaluate levels --model analytic:{W}/a/arm3.xml:smell --out {W}/res"),
    ("levels-two-arms-one-name", "evaluate levels --model analytic:{W}/a/arm3.xml:ee_xyz "
                                 "--model analytic:{W}/b/arm3.xml:ee_pixel --trials 2 --runs 1 --out {W}/res"),
    ("reaching-models-of-another-robot", "evaluate reaching --robot {W}/a/arm3.xml --model analytic:planar2:ee_xyz "
                                         "--trials 1 --out {W}/res"),
    ("self-recognition-not-a-model", "evaluate self-recognition --robot {W}/arm.sdf --trials 2 --out {W}/res"),
    ("self-recognition-another-robot", "evaluate self-recognition --robot {W}/a/arm3.xml "
                                       "--model analytic:planar2:ee_pixel --trials 2 --out {W}/res"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    w = tmp_path_factory.mktemp("file_robot_world")
    write_arm(w / "a")
    write_arm(w / "b", upper=0.3)
    (w / "arm.sdf").write_text("<sdf/>")
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_file_robot_input_is_a_clear_error(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)

