"""Issue 33 item 2: a robot record may name several cameras. Each further camera of the model file is one more image
modality, image_<camera>, rendered at the robot's image size, held in the store beside the robot's own image,
reported by the observability table and perceived together with the others (one model per camera, one z)."""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest
import torch

from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.base import modalities
from bodyschema.datagen.body.record import read_record, shipped_dir, write_record
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.schema import features
from bodyschema.datagen.store.validate import validate_store
from tests.aif.toys import ToyBlobImage, perturb, planar_poses

SIDE = '<camera name="side" pos="0.8 -0.8 0.6" xyaxes="1 1 0 -0.6 0.6 1.6" fovy="60" mode="fixed"/>'


def two_camera_record(tmp_path, cameras=("side",), size=(32, 32)):
    """planar2 with a second camera `side` in its model file, and a record naming `cameras`."""
    xml = (shipped_dir() / "planar2.xml").read_text()
    (tmp_path / "planar2.xml").write_text(re.sub(r"(<camera name=\"eye\"[^>]*/>)", r"\1" + SIDE, xml))
    shipped = read_record(shipped_dir() / "planar2.toml")
    from dataclasses import replace
    record = replace(shipped, name="twocam", image_size=size, cameras=tuple(cameras), reaching={}, base=tmp_path)
    return write_record(record, tmp_path / "twocam.toml")


def test_a_further_camera_is_an_image_modality_by_rule():
    row = modalities.find("image_wrist")
    assert row.is_image and row.camera == "wrist" and row.dtype == "uint8" and row.precision is None
    assert modalities.is_image("image_wrist") and modalities.get("image_wrist") == row
    assert modalities.unit("image_wrist") == modalities.unit("image")
    assert modalities.find("image_") is None and modalities.find("imagery") is None
    assert not modalities.is_image("image_a b")                           # not a camera name
    with pytest.raises(ValueError, match="camera name must be"):
        modalities.camera_modality("a/b")


def test_the_store_holds_a_further_camera_only_for_robots_that_have_it():
    with_it = features(2, (8, 12), sensors=("image_side",), babble=False)
    assert modalities.images_in(with_it) == ["image", "image_side"]
    assert with_it["image_side"] == with_it["image"]                      # same dtype, shape, unit, names
    assert "image_side" not in features(2, (8, 12), sensors=(), babble=False)
    assert "image_side" not in features(2, None, sensors=("image_side",), babble=False)   # no images: no camera


def test_a_robot_renders_every_camera_of_its_record(tmp_path):
    with Robot.load(two_camera_record(tmp_path)) as robot:
        assert list(robot.cameras) == ["image", "image_side"] and robot.sensors == ("image_side", "ee_pixel_side")
        q = np.array([[0.3, -0.7], [1.1, 0.4]])
        seen = robot.observe(q)
        assert seen["image_side"].shape == seen["image"].shape == (2, 32, 32)
        assert not np.array_equal(seen["image_side"], seen["image"])     # another view
        assert not np.array_equal(seen["image_side"][0], seen["image_side"][1])   # the arm moves in it
        np.testing.assert_array_equal(robot.render(q, modality="image_side"), seen["image_side"])
        with pytest.raises(ValueError, match=r"modality must be one of twocam's cameras \['image', 'image_side'\]"):
            robot.render(q, modality="image_top")


def test_a_further_camera_may_be_placed_by_the_record(tmp_path):
    """A URDF has no cameras: a further camera is then a pose, as [camera] places one; written and read back."""
    placed = {"name": "low", "pos": [0.9, 0.0, 0.4], "xyaxes": [0.0, 1.0, 0.0, -0.4, 0.0, 0.9], "fovy": 50.0}
    path = two_camera_record(tmp_path, ("side", placed))
    record = read_record(path)
    assert record.cameras == ("side", placed) and record.further_cameras == ("side", "low")
    with Robot.load(record) as robot:
        assert list(robot.cameras) == ["image", "image_side", "image_low"]
        seen = robot.observe(np.array([[0.3, -0.7]]))
        assert seen["image_low"].shape == (1, 32, 32) and seen["image_low"].any()


@pytest.mark.parametrize("cameras, words", [
    (("top",), r"cameras must be one of the model's cameras \['eye', 'side'\] for twocam. Got 'top'"),
    (("eye",), "further cameras, without the record's \\[camera\\]"),
    (("side", "side"), "distinct camera names"),
    (("a/b",), "distinct camera names"),
    (({"name": "low", "pos": [1, 0, 0], "fovy": 50},), r"record \[camera\] must be pos"),
    (({"name": "low"},), "a camera name of the model file or {name, pos, xyaxes, fovy}"),
])
def test_a_record_naming_a_camera_it_cannot_have_is_refused(tmp_path, cameras, words):
    with pytest.raises(ValueError, match=words):
        Robot.load(two_camera_record(tmp_path, cameras))


def test_datagen_stores_and_reports_each_camera(tmp_path, caplog):
    record = two_camera_record(tmp_path)
    with caplog.at_level(logging.INFO):
        path = generate(DatagenConfig(robot=str(record), n=32, shard_size=16, seed=0, out=tmp_path / "s.zarr"),
                        progress=False)
    assert validate_store(path) == []
    import zarr
    root = zarr.open_group(str(path), mode="r")
    with Robot.load(record) as robot:
        q = root["q"][:].astype(np.float64)
        np.testing.assert_array_equal(root["image_side"][:], robot.render(q, modality="image_side"))
    tables = [r.getMessage() for r in caplog.records if r.getMessage().startswith("observability: camera")]
    assert [t.split("'")[1] for t in tables] == ["eye", "side"]
    from bodyschema.datagen.store.show import store_observability
    shown = store_observability(path)                                    # `bodyschema show`: each camera too
    assert "observability: camera 'eye'" in shown and "observability: camera 'side'" in shown


class SideBlob(ToyBlobImage):
    """The blob toy seen by a second camera: modality image_side, its grid shifted and coarser."""

    def __init__(self):
        super().__init__()
        self.modality = "image_side"
        self.gx, self.gy = 1.5 * self.gx + 0.1, 1.5 * self.gy - 0.1


def test_perception_fuses_two_cameras_over_one_z():
    own, side = ToyBlobImage(), SideBlob()
    q = planar_poses(12, seed=5)
    obs = {"image": own.predict(q), "image_side": side.predict(q)}
    both = Perception([own, side], PerceptionConfig())
    assert both.config.method == "adam+lm"                             # "auto" reads both as images
    result = both.infer(obs, perturb(q, seed=6, max_rad=0.3))
    assert torch.allclose(result.mu, q, atol=1e-4)
    _, terms = both.energies(obs, q)
    assert set(terms) == {"image", "image_side"}


def test_robot_camera_add_places_a_second_view_for_the_joints_the_first_does_not_see(tmp_path, capsys, monkeypatch):
    """`robot camera --add`: the record names a placed second view and the robot renders it; the joints it reports
    unseen are those under the threshold in both views (the pair never sees less than the first alone)."""
    from bodyschema.cli import main
    from bodyschema.datagen.body import camera_choice
    from bodyschema.datagen.body.camera_choice import FURTHER
    from bodyschema.datagen.body.observability import MIN_PX_PER_DEG, every_camera
    every = camera_choice._framings
    monkeypatch.setattr(camera_choice, "_framings", lambda covers=camera_choice.COVERS: every(covers)[::6])  # the
    # suite's time: 1 in 6 of the views
    path = two_camera_record(tmp_path, cameras=(), size=(16, 16))       # small: joints near the threshold
    assert main(["robot", "camera", str(path), "--add"]) == 0
    written = read_record(path)
    assert written.further_cameras == (FURTHER,) and {"pos", "xyaxes", "fovy"} <= set(written.cameras[0])
    with Robot.load(written) as robot:
        assert robot.observe(np.array([[0.2, 0.5]]))["image_auto2"].shape == (1, *written.image_size)
        first, second = every_camera(robot)                              # as the command measured them
    best = np.maximum([j.px_per_deg for j in first.joints], [j.px_per_deg for j in second.joints])
    unseen = ", ".join(j.name for j, px in zip(first.joints, best) if px < MIN_PX_PER_DEG) or "none"
    out = capsys.readouterr().out
    assert "further camera 'auto2' (image_auto2)" in out
    assert f"joints seen by neither camera (< the threshold in both): {unseen}" in out


def test_a_close_up_that_loses_the_ee_in_some_poses_may_be_the_second_view_never_the_first(tmp_path, monkeypatch):
    """Only close-ups offered (framing half the ee positions: on planar2 the ee leaves them in ~37 % of poses): the
    first camera refuses them all (it must see the ee in GOOD_VIEW of the poses), the second view takes one, and
    its ee is in view in fewer than GOOD_VIEW but at least MIN_VIEW of the poses."""
    import dataclasses

    from bodyschema.datagen.body import camera_choice
    from bodyschema.datagen.body.infer import GOOD_VIEW, MIN_VIEW, view_fraction
    from bodyschema.datagen.body.observability import every_camera
    every = camera_choice._framings
    monkeypatch.setattr(camera_choice, "_framings", lambda covers=camera_choice.COVERS:
                        [f for f in every(camera_choice.FURTHER_COVERS) if f.get("cover") == 0.5][:3])
    record = read_record(two_camera_record(tmp_path, cameras=(), size=(16, 16)))
    with Robot.load(record) as robot:
        box, first = robot.sampling_ranges, every_camera(robot)[0]
    with pytest.raises(ValueError, match=r"a camera framing the ee of robot 'twocam' must be able to see it in "
                                         r"at least 90% of the poses\. Got 'none of 3 views and framings'"):
        camera_choice.choose_camera(record, box)
    chosen = camera_choice.choose_further_camera(record, box, first)
    with Robot.load(dataclasses.replace(record, camera=chosen.camera, cameras=())) as close_up:
        assert MIN_VIEW <= view_fraction(close_up, box) < GOOD_VIEW
