"""`bodyschema import --robot FILE`: a recording of an arm from an MJCF file (with its robot record) imports like one
of a shipped robot, and the store is self-contained: it keeps the record and the model text, so its robot (for
forward kinematics, levels on recorded targets) is rebuilt after the model file is gone."""

from __future__ import annotations

import shutil

import numpy as np

from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.datagen.store.schema import open_store
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.import_sources import write_folder
from tests.evaluation.test_file_robot import write_arm


def test_a_file_robots_recording_imports_and_keeps_its_robot(tmp_path):
    arm = write_arm(tmp_path / "arm")
    with Robot.load(str(arm)) as robot:
        q = np.random.default_rng(0).uniform(*robot.sampling_ranges.T, size=(8, robot.dq))
        images, names = robot.observe(q)["image"], robot.joint_names
    folder = write_folder(tmp_path / "rec", q, images, names=names)
    store = import_recording(ImportConfig(source=folder, out=tmp_path / "rec.zarr", angles="deg", robot=str(arm),
                                          fk=True))
    assert validate_store(store) == []
    shutil.rmtree(arm.parent)                                    # the model file is gone: the store suffices
    attrs = dict(open_store(store).attrs)
    with Robot.from_attrs(attrs, image_size=None) as rebuilt:
        stored_q = np.asarray(open_store(store)["q"][:], float)
        np.testing.assert_allclose(rebuilt.fk(stored_q), open_store(store)["ee_xyz"][:], atol=1e-6)
    assert attrs["robot_model"]["sha256"] == attrs["mjcf_sha256"]
