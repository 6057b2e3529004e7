"""The ee projected into each further camera of a record (ee_pixel_<camera>): a row by rule beside ee_pixel, written
by datagen with or without images, checked by `validate_store` against the camera the store's attrs describe, and
an exact model (`analytic:ROBOT:ee_pixel_<camera>`) whose Jacobian equals finite differences."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import zarr

from bodyschema.base import modalities
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.schema import features
from bodyschema.datagen.store.validate import validate_store
from bodyschema.models.analytic import AnalyticModel
from tests.datagen.test_several_cameras import two_camera_record


def test_a_further_camera_has_its_ee_projection_by_rule():
    row = modalities.find("ee_pixel_side")
    assert row == modalities.get("ee_pixel_side") and row.unit == "px" and row.shape == (2,) and not row.is_image
    assert modalities.pixel_modality("image_side") == "ee_pixel_side"
    assert modalities.pixel_modality("image") == "ee_pixel"
    assert modalities.is_projection("ee_pixel_side") and modalities.is_projection("ee_pixel")
    assert modalities.find("ee_pixel_") is None and not modalities.is_projection("ee_xyz")
    assert not modalities.is_projection("ee_pixel_a b")                            # not a camera name
    kinematics_only = features(2, None, sensors=("image_side", "ee_pixel_side"), babble=False)   # from q: no images
    assert kinematics_only["ee_pixel_side"] == kinematics_only["ee_pixel"]
    assert "ee_pixel_side" not in features(2, (8, 12), sensors=("image_side",), babble=False)   # a camera riding
                                                                                                # on a link: none
    assert "ee_pixel_side" not in features(2, (8, 12), sensors=(), babble=False)


@pytest.mark.parametrize("images", [True, False])
def test_datagen_writes_each_cameras_projection_and_validate_checks_it(tmp_path, images):
    record = two_camera_record(tmp_path)
    path = generate(DatagenConfig(robot=str(record), n=32, shard_size=16, seed=0, out=tmp_path / "s.zarr",
                                  images=images), progress=False)
    assert validate_store(path) == []
    root = zarr.open_group(str(path), mode="r+")
    with Robot.load(record) as robot:
        q = root["q"][:].astype(np.float64)
        expected = robot.project(robot.fk(q), "ee_pixel_side")
        assert not np.allclose(expected, robot.project(robot.fk(q)))              # another camera, other pixels
    np.testing.assert_allclose(root["ee_pixel_side"][:], expected, atol=1e-3)     # float32 storage
    assert set(root.attrs["camera_views"]) == {"ee_pixel_side"}
    shifted = root["ee_pixel_side"][:]
    shifted[5] += 0.5                                                             # one row half a pixel off
    root["ee_pixel_side"][:] = shifted
    problems = validate_store(path)
    assert any("ee_pixel_side must be ee_xyz projected through attrs camera_views['ee_pixel_side']" in p
               and "1 rows off by up to 0.5 px, first at row 5" in p for p in problems), problems


def test_the_exact_projection_into_a_further_camera_has_its_jacobian(tmp_path):
    model = AnalyticModel(str(two_camera_record(tmp_path)), "ee_pixel_side")
    z = torch.tensor([[0.3, -0.7], [1.1, 0.4]], dtype=torch.float64)
    assert torch.allclose(model.predict(z), torch.from_numpy(model.robot.project(model.robot.fk(z.numpy()),
                                                                                 "ee_pixel_side")))
    eps = 1e-6
    columns = [(model.predict(z + eps * e) - model.predict(z - eps * e)) / (2 * eps) for e in torch.eye(2)]
    torch.testing.assert_close(model.jacobian(z), torch.stack(columns, -1), atol=1e-4, rtol=1e-6)  # px/rad, FD error
    assert model.precision(z).shape == (2, 2)


def test_a_projection_into_a_camera_the_robot_lacks_is_the_house_error(tmp_path):
    with pytest.raises(ValueError, match=r"modality must be one of twocam's projections \['ee_pixel', "
                                         r"'ee_pixel_side'\]. Got 'ee_pixel_top'"):
        AnalyticModel(str(two_camera_record(tmp_path)), "ee_pixel_top")
    with Robot.load(two_camera_record(tmp_path)) as robot, pytest.raises(ValueError, match="projections"):
        robot.project(np.zeros((1, 3)), "ee_pixel_top")


def test_the_levels_sense_a_further_cameras_projection(tmp_path):
    """The levels' targets hold every projection the robot has, each through its own camera."""
    from bodyschema.evaluation.levels.targets import make_targets

    with Robot.load(two_camera_record(tmp_path)) as robot:
        targets = make_targets(robot, 4, np.random.default_rng(0))
        xyz = robot.fk(targets.q)
        np.testing.assert_allclose(targets.observations["ee_pixel_side"], robot.project(xyz, "ee_pixel_side"))
        np.testing.assert_allclose(targets.observations["ee_pixel"], robot.project(xyz))
        assert set(targets.tensors(["ee_pixel", "ee_pixel_side"])) == {"ee_pixel", "ee_pixel_side"}


def test_the_loop_benchmarks_sense_each_camera_through_itself(tmp_path):
    """`sense` (reaching, tracking, robustness) reads image_<c> and ee_pixel_<c> from camera c, not the robot's own."""
    from bodyschema.evaluation.core.sensing import sense, sense_all
    from bodyschema.models.scaling import IMAGE_SCALE

    with Robot.load(two_camera_record(tmp_path)) as robot:
        q = np.array([[0.3, -0.7], [1.1, 0.4]])
        side = robot.render(q, modality="image_side") / IMAGE_SCALE
        np.testing.assert_array_equal(sense(robot, "image_side", q), side)
        assert not np.array_equal(sense(robot, "image", q), side)
        read = sense_all(robot, ["ee_pixel_side", "ee_pixel"], q)
        np.testing.assert_allclose(read["ee_pixel_side"].numpy(), robot.project(robot.fk(q), "ee_pixel_side"))
        assert not np.allclose(read["ee_pixel_side"].numpy(), read["ee_pixel"].numpy())
