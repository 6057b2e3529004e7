"""The servos the robot builder adds are integrated with their damping implicit (`implicitfast`) when the file names
no integrator: under Euler, kv·timestep/M > 2 diverges on light links (TALOS's elbow); a file's own choice stays."""

import shutil

import mujoco
import pytest

from bodyschema.datagen.body.infer import infer_record
from bodyschema.datagen.body.robot import Robot
from tests.datagen.test_robot_foreign import _package_file


@pytest.fixture(scope="module")
def jaco_folder(tmp_path_factory):
    """dm_control's Jaco (its file names no integrator) copied with its meshes, so the test can edit the file."""
    source = _package_file("dm_control", "dm_control/third_party/kinova")
    folder = tmp_path_factory.mktemp("jaco") / "kinova"
    shutil.copytree(source, folder)
    return folder


def test_a_file_without_an_integrator_gets_implicit_servos(jaco_folder):
    record = infer_record(jaco_folder / "jaco_arm.xml")
    assert record.actuators["kind"] == "servos"
    with Robot.load(record) as robot:
        assert robot.model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def test_a_file_that_names_its_integrator_keeps_it(jaco_folder):
    text = (jaco_folder / "jaco_arm.xml").read_text()
    assert "<option" not in text
    edited = jaco_folder / "jaco_rk4.xml"
    edited.write_text(text.replace("<worldbody>", '<option integrator="RK4"/>\n  <worldbody>', 1))
    with Robot.load(infer_record(edited)) as robot:
        assert robot.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
