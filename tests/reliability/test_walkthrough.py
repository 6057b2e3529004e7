"""Defects found walking the README's "Your own robot" on a UR5 URDF (issue 20): a record whose ee is a body plus an
offset names its ee site `bodyschema_ee`, and the benchmarks' simulator looked the site up as "ee" (reaching stopped
with an internal KeyError after its goal inference)."""

from __future__ import annotations

import numpy as np

from bodyschema.control.sim import ArmBatch
from bodyschema.datagen.body.record import dumps_toml
from bodyschema.datagen.body.robot import Robot
from tests.evaluation.test_file_robot import ARM, RECORD


def test_the_simulator_follows_an_ee_given_as_a_body_plus_offset(tmp_path):
    (tmp_path / "arm3.xml").write_text(ARM.format(upper=0.25))
    record = {**RECORD, "ee": {"body": "lower", "offset": [0.0, 0.0, 0.15]}}
    (tmp_path / "arm3.toml").write_text(dumps_toml(record))
    q0 = np.array([[0.3, -0.4, 0.9], [-1.0, 0.5, -0.2]])
    with Robot.load(str(tmp_path / "arm3.toml")) as robot, ArmBatch(robot, q0) as arm:
        assert robot.ee_site != "ee"
        np.testing.assert_allclose(arm.ee_xyz, robot.fk(arm.q), atol=1e-9)
        lower = robot.model.body("lower").id
        assert int(robot.model.site_bodyid[robot.model.site(robot.ee_site).id]) == lower
