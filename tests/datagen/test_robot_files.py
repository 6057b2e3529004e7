"""A robot from a file: inferred records, welding held joints, a placed camera, `robot init/show`, datagen on a file
robot, and a store that rebuilds its robot from its attrs alone (issue 20 parts 1-3). Toy MJCFs written here."""

import dataclasses
import shutil

import mujoco
import numpy as np
import pytest

from bodyschema.cli import main
from bodyschema.datagen.body.infer import infer_record, view_fraction
from bodyschema.datagen.body.record import load_record, read_record, shipped_dir
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.schema import open_store
from bodyschema.datagen.store.validate import validate_store

# A 3-hinge arm on a slide rail, no site named ee, no camera: everything but the model is inferred.
TOY = """<mujoco model="toy">
  <compiler angle="radian"/>
  <worldbody>
    <body name="rail">
      <joint name="rail" type="slide" axis="1 0 0" range="-0.2 0.2"/>
      <geom type="box" size="0.05 0.05 0.02" mass="1"/>
      <body name="upper" pos="0 0 0.05">
        <joint name="shoulder" axis="0 1 0" range="-1.5 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.02" mass="0.3"/>
        <body name="lower" pos="0 0 0.3" euler="0 0.3 0">
          <joint name="elbow" axis="0 1 0" pos="0 0 0.01"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.25" size="0.02" mass="0.2"/>
          <body name="hand" pos="0 0 0.25">
            <joint name="wrist" axis="1 0 0" range="-1 1"/>
            <geom type="sphere" size="0.03" mass="0.05" rgba="1 1 0 1"/>
            <site name="tip" pos="0 0 0.04"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    path = tmp_path_factory.mktemp("toy") / "toy.xml"
    path.write_text(TOY)
    return path


def test_the_inferred_record_names_the_chain_holds_the_rest_and_places_a_camera(toy):
    record = infer_record(toy)
    assert record.joints == ("shoulder", "elbow", "wrist") and record.ee == {"site": "tip"}
    assert record.workspaces["full"][1] == (-np.pi, np.pi)                # a continuous hinge gets ±π
    assert record.actuators["kind"] == "servos" and min(record.actuators["kp"]) > 0
    with Robot.load(record) as robot:
        assert robot.dq == 3 and robot.model.nu == 3 and robot.actuation == "position"
        assert view_fraction(robot, robot.workspaces["full"]) > 0.95     # framed from sampled FK
        assert robot.render(robot.sampling_ranges.mean(axis=1)[None]).std() > 0


def test_welded_joints_keep_the_forward_kinematics_of_the_whole_model(toy, tmp_path):
    shutil.copy(toy, tmp_path / "toy.xml")
    values = infer_record(tmp_path / "toy.xml").to_toml_dict()
    values["hold"] = {"rail": 0.1}
    (tmp_path / "toy.toml").write_text(_toml(values))
    robot = Robot.load(tmp_path / "toy.xml")                              # the record beside the file
    assert robot.record.hold == {"rail": 0.1}
    full = mujoco.MjModel.from_xml_string(TOY)
    data = mujoco.MjData(full)
    q = np.random.default_rng(0).uniform(robot.joint_limits[:, 0], robot.joint_limits[:, 1], (300, 3))
    expected = []
    for q_i in q:
        data.qpos[:] = [0.1, *q_i]
        mujoco.mj_kinematics(full, data)
        expected.append(data.site("tip").xpos.copy())
    np.testing.assert_allclose(robot.fk(q), np.array(expected), atol=1e-12)
    np.testing.assert_allclose(robot.fk_and_jacobian(q)[0], np.array(expected), atol=1e-12)   # the vectorized chain


def test_a_store_rebuilds_its_robot_without_the_model_file(toy, tmp_path):
    model = tmp_path / "arm" / "toy.xml"
    model.parent.mkdir()
    shutil.copy(toy, model)
    store = generate(DatagenConfig(robot=str(model), n=8, shard_size=8, out=tmp_path / "toy.zarr"), progress=False)
    assert validate_store(store) == []
    attrs = dict(open_store(store).attrs)
    assert attrs["robot"] == "toy" and attrs["robot_model"]["sha256"] == attrs["mjcf_sha256"]
    shutil.rmtree(model.parent)                                           # the file moved away
    root = open_store(store)
    with Robot.from_attrs(attrs) as robot:
        q = np.asarray(root["q"][:], dtype=np.float64)
        np.testing.assert_allclose(robot.fk(q), root["ee_xyz"][:], atol=1e-6)
        np.testing.assert_array_equal(robot.render(q), root["image"][:])


def test_a_shipped_store_rebuilds_the_same_robot(tmp_path):
    store = generate(DatagenConfig(robot="planar2", n=4, images=False, out=tmp_path / "p.zarr"), progress=False)
    attrs = dict(open_store(store).attrs)
    robot = Robot.from_attrs(attrs)
    assert robot.record == load_record("planar2").__class__(**{**load_record("planar2").__dict__,
                                                               "model": str(shipped_dir() / "planar2.xml"),
                                                               "base": robot.record.base})
    q = np.asarray(open_store(store)["q"][:], dtype=np.float64)
    np.testing.assert_allclose(robot.fk(q), open_store(store)["ee_xyz"][:], atol=1e-6)


def test_robot_init_writes_the_inferred_record_and_show_draws_the_robot(toy, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shutil.copy(toy, tmp_path / "toy.xml")
    assert main(["robot", "init", "toy.xml"]) == 0
    record = read_record(tmp_path / "toy.toml")
    assert record.model_path == (tmp_path / "toy.xml").resolve() and record.camera["name"] == "auto"
    assert main(["robot", "init", "toy.xml"]) == 2                      # an existing record is kept
    assert main(["robot", "show", "toy.xml", "--n", "4"]) == 0
    out = capsys.readouterr().out
    assert "shoulder: [-1.5000, 1.5000] rad" in out and "ee in view: 100.0%" in out and "sites: tip" in out
    assert (tmp_path / "toy_robot_sheet.png").stat().st_size > 0


def test_robot_camera_frames_a_narrowed_workspace_closer_and_keeps_the_rest(toy, tmp_path, capsys):
    shutil.copy(toy, tmp_path / "toy.xml")
    assert main(["robot", "init", str(tmp_path / "toy.xml")]) == 0
    path = tmp_path / "toy.toml"
    narrow = ((-0.3, 0.3), (0.2, 0.8), (-0.3, 0.3))
    path.write_text(path.read_text().replace("[workspaces]", f"[workspaces]\nnear = {_toml({'x': narrow})[4:]}"))
    before = read_record(path)
    assert main(["robot", "camera", str(path), "--workspace", "near"]) == 0
    after = read_record(path)
    with Robot.load(after) as robot:
        centre = robot.fk(np.array(narrow).mean(axis=1)[None])[0]
        assert view_fraction(robot, np.array(narrow)) > 0.95
    far, near = (np.linalg.norm(np.array(r.camera["pos"]) - centre) for r in (before, after))
    assert near < 0.7 * far                                              # a smaller box is framed from nearer
    assert max(after.image_size) <= 128                                  # grown only to see more joints, bounded
    assert dataclasses.replace(after, camera=before.camera, image_size=before.image_size) == before   # nothing else
    assert path.read_text().startswith("# Robot record of toy.xml")      # the header is kept
    text = path.read_text()
    assert main(["robot", "camera", str(path), "--workspace", "far"]) == 2
    assert "--workspace must be one of the record's ['camera', 'full', 'near']" in capsys.readouterr().err
    assert main(["robot", "camera", str(tmp_path / "toy.xml")]) == 2
    assert path.read_text() == text                                      # refused: the record is untouched


def _toml(values):
    from bodyschema.datagen.body.record import dumps_toml
    return dumps_toml(values)
