"""README "Adding a robot-file format": one row in datagen/body/formats.py (a suffix and a reader returning a MuJoCo
spec). A toy format, `.arm` (one link length in metres per line, a planar chain of hinges), registered at run time:
`robot init` infers its record, `Robot` computes its kinematics and renders it, the record refuses a suffix no row
reads, with no other file of the package edited."""

from __future__ import annotations

import numpy as np
import pytest

from bodyschema.cli import main
from bodyschema.datagen.body import formats
from bodyschema.datagen.body.infer import infer_record
from bodyschema.datagen.body.mjcf import read_mjcf
from bodyschema.datagen.body.record import RobotRecord
from bodyschema.datagen.body.robot import Robot


def arm_to_mjcf(text: str) -> str:
    """A planar chain of hinges about z, each link the length on its line (m), ending in a hand."""
    lengths = [float(line) for line in text.split() if line.strip()]
    body = '<body name="hand" pos="{:g} 0 0"><geom type="box" size="0.03 0.03 0.03"/></body>'.format(lengths[-1])
    for i, length in reversed(list(enumerate(lengths))):
        parent = f"{lengths[i - 1]:g} 0 0" if i else "0 0 0"
        body = (f'<body name="link{i}" pos="{parent}"><joint name="j{i}" type="hinge" axis="0 0 1" range="-2 2"/>'
                f'<geom type="capsule" fromto="0 0 0 {length:g} 0 0" size="0.02"/>{body}</body>')
    return (f'<mujoco model="toy_arm"><compiler angle="radian"/><visual><quality shadowsize="0"/></visual><worldbody>'
            f'<light pos="0 0 3"/>{body}</worldbody></mujoco>')


def read_arm(path, text, record, budget):
    """The reader contract of formats.py: the spec of `text`, its files' digests, links drawn as primitives."""
    return read_mjcf(path, arm_to_mjcf(text), record, budget)


@pytest.fixture
def arm_format(tmp_path):
    formats.register(formats.Format("toy arm", ".arm", read_arm))
    yield tmp_path / "toy.arm"
    formats.unregister(".arm")


def test_a_registered_format_is_a_robot_from_init_to_images(arm_format):
    arm_format.write_text("0.4\n0.3\n")
    record = infer_record(arm_format)
    assert record.joints == ("j0", "j1")
    with Robot.load(record, image_size=(32, 32)) as robot:
        ee = robot.fk(np.zeros((1, 2)), check=False)[0]
        np.testing.assert_allclose(ee[:2], [0.7, 0.0], atol=1e-6)          # the hand at the sum of the links
        bent = robot.fk(np.array([[np.pi / 2, 0.0]]), check=False)[0]
        np.testing.assert_allclose(bent[:2], [0.0, 0.7], atol=1e-6)
        assert robot.render(np.zeros((1, 2))).max() > 0                      # the camera sees it


def test_robot_init_takes_a_registered_suffix_and_the_record_names_the_formats(arm_format, tmp_path, capsys):
    arm_format.write_text("0.4\n0.3\n")
    assert main(["robot", "init", str(arm_format), "--out", str(tmp_path / "toy.toml")]) == 0
    assert "toy arm (.arm)" in formats.described()
    formats.unregister(".arm")
    with pytest.raises(ValueError, match=r"record `model` must be a path to an MJCF \(\.xml\) or URDF \(\.urdf\) "):
        RobotRecord(name="toy", model="toy.arm", image_size=(32, 32), workspaces={"full": ((-1, 1),),
                                                                                  "camera": ((-1, 1),)})


def test_a_format_row_must_bring_a_new_suffix():
    with pytest.raises(ValueError, match="new lower-case suffix"):
        formats.register(formats.Format("again", ".urdf", read_arm))
    with pytest.raises(ValueError, match="new lower-case suffix"):
        formats.register(formats.Format("no dot", "arm", read_arm))
