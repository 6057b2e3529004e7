"""Robot records: one TOML per robot holds what the model file does not; the shipped robots are records too."""

import math

import numpy as np
import pytest

from bodyschema.datagen.body.record import (
    SHIPPED,
    RobotRecord,
    dumps_toml,
    load_record,
    read_record,
    record_from_dict,
    shipped_dir,
    write_record,
)
from bodyschema.datagen.body.robot import Robot


@pytest.mark.parametrize("name", SHIPPED)
def test_each_shipped_robot_is_a_record_beside_its_mjcf(name):
    record = load_record(name)
    assert record.name == name and record.model_path == shipped_dir() / f"{name}.xml"
    robot = Robot.load(name)
    assert robot.record == record and robot.camera_name == record.camera_name
    assert robot.image_size == record.image_size
    for ws, box in record.workspaces.items():
        assert np.array_equal(robot.workspaces[ws], np.array(box))


def test_the_robot_tables_are_gone():
    import bodyschema.control.pd as pd
    import bodyschema.datagen.body.robot as robot
    import bodyschema.datagen.config as config
    import bodyschema.evaluation.reaching.benchmark as reaching
    assert not hasattr(robot, "ROBOT_DEFAULTS") and not hasattr(config, "ROBOTS")
    assert not hasattr(reaching, "ROBOTS") and not hasattr(pd, "FRANKA_KP")


def test_a_record_written_reads_back_equal_floats_included(tmp_path):
    box = ((-2.8973 * 0.95, math.pi / 3), (0.1 + 0.2, 1.0))
    record = RobotRecord(name="arm", model="arm.xml", image_size=(48, 64), workspaces={"full": box, "camera": box},
                         ee={"body": "hand", "offset": [0.0, 0.0, 0.1]}, joints=("a", "b"), hold={"c": 0.3},
                         camera={"name": "auto", "pos": [1.0, 2.0, 3.0], "xyaxes": [1, 0, 0, 0, 1, 0], "fovy": 45.0},
                         actuators={"kind": "servos", "kp": [1.5, 2.0], "kv": [0.1, 0.2]},
                         pd={"kp": [1, 2], "kd": [3, 4]},
                         reaching={"models": ["ee_xyz"], "action": {"k_a": 0.25}}, collisions="none", base=tmp_path)
    back = read_record(write_record(record, tmp_path / "arm.toml", "a header\nof two lines"))
    assert back == record
    assert not list(tmp_path.glob(".*.tmp"))                               # the temporary sibling is gone


def test_the_toml_writer_nests_tables():
    text = dumps_toml({"a": 1, "t": {"x": [1.5, 2], "u": {"k": "v"}}})
    assert "[t]" in text and "[t.u]" in text and 'k = "v"' in text


@pytest.mark.parametrize("change, words", [
    ({"colour": "red"}, "keys of"),
    ({"workspaces": {"full": [[0, 1]]}}, "including ('full', 'camera')"),
    ({"ee": {"site": "ee", "body": "hand"}}, "either site"),
    ({"ee": {"body": "hand", "offset": [0, 0]}}, "offset must be"),
    ({"image_size": [4, 64]}, "image_size"),
    ({"model": "arm.sdf"}, "MJCF (.xml) or URDF"),
    ({"camera": {"name": "auto", "pos": [0, 0, 1]}}, "xyaxes"),
    ({"actuators": {"kind": "servos", "kp": [1]}}, "kp and kv"),
    ({"actuators": {"kind": "muscles"}}, "kind must be one of"),
    ({"workspaces": {"full": [[1, 0]], "camera": [[0, 1]]}}, "lo < hi"),
    ({"collisions": "self"}, "collisions` must be one of"),
])
def test_a_bad_record_is_the_house_error(tmp_path, change, words):
    values = {"name": "arm", "model": "arm.xml", "image_size": [64, 64], "camera": {"name": "eye"},
              "workspaces": {"full": [[0.0, 1.0]], "camera": [[0.0, 1.0]]}, **change}
    with pytest.raises(ValueError, match="must be") as info:
        record_from_dict(values, tmp_path)
    assert words in str(info.value)


def test_a_record_of_another_model_file_is_refused(tmp_path):
    (tmp_path / "a.xml").write_text("<mujoco/>")
    (tmp_path / "a.toml").write_text('name = "a"\nmodel = "b.xml"\nimage_size = [8, 8]\n[camera]\nname = "c"\n'
                                     '[workspaces]\nfull = [[0.0, 1.0]]\ncamera = [[0.0, 1.0]]\n')
    with pytest.raises(ValueError, match="about a.xml"):
        load_record(tmp_path / "a.xml")
    (tmp_path / "bad.toml").write_text("name = ")
    with pytest.raises(ValueError, match="valid TOML"):
        load_record(tmp_path / "bad.toml")
