"""Issue 33 item 2: a further camera may ride on a link (`body`), as the wrist cameras of LeRobot's arms: it moves with
the link, has no fixed projection (no ee_pixel_<name>), and `robot camera --mount` places one framing the bodies
beyond the link. The record's own camera stays fixed in the world (it gives ee_pixel and frames the workspace)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
import zarr

from bodyschema.datagen.body.camera import FixedCamera
from bodyschema.datagen.body.camera_mount import MOUNTED, choose_mount, mount_camera
from bodyschema.datagen.body.commands import RobotCameraArgs, run_camera
from bodyschema.datagen.body.observability import observability
from bodyschema.datagen.body.record import read_record, record_from_dict, shipped_dir, write_record
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.validate import validate_store

ON_LINK1 = {"name": "wrist", "pos": [0.3, 0.0, 0.4], "xyaxes": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "fovy": 60.0,
            "body": "link1"}


def planar2_with(tmp_path, *cameras, size=(32, 32)):
    shipped = read_record(shipped_dir() / "planar2.toml")
    record = dataclasses.replace(shipped, name="mounted2", image_size=size, cameras=tuple(cameras), reaching={},
                                 model=str(shipped.model_path))
    return write_record(record, tmp_path / "mounted2.toml")


def test_a_mounted_camera_rides_on_its_link(tmp_path):
    """At every pose the camera's world pose is its link's pose composed with the record's pos and axes."""
    with Robot.load(planar2_with(tmp_path, ON_LINK1)) as robot:
        model, data = robot.model, mujoco.MjData(robot.model)
        cam, link = model.camera("wrist").id, model.body("link1").id
        for q in np.random.default_rng(0).uniform(-2.5, 2.5, (5, 2)):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            frame = data.xmat[link].reshape(3, 3)
            np.testing.assert_allclose(data.cam_xpos[cam], data.xpos[link] + frame @ ON_LINK1["pos"], atol=1e-12)
            axes = data.cam_xmat[cam].reshape(3, 3)                     # columns: the camera's x, y, z in the world
            np.testing.assert_allclose(axes[:, :2].T, (frame @ np.reshape(ON_LINK1["xyaxes"], (2, 3)).T).T,
                                       atol=1e-12)
        assert robot.projections() == ("ee_pixel",)                   # a moving camera: no fixed projection
        assert robot.sensors == ("image_wrist",)


def test_datagen_stores_a_mounted_cameras_images_and_no_projection(tmp_path):
    path = generate(DatagenConfig(robot=str(planar2_with(tmp_path, ON_LINK1)), n=16, shard_size=8, seed=0,
                                  out=tmp_path / "s.zarr"), progress=False)
    root = zarr.open_group(path, mode="r")
    assert "image_wrist" in root and "ee_pixel_wrist" not in root
    assert root["image_wrist"].shape == root["image"].shape
    assert validate_store(path) == []


def test_a_stores_robot_renders_its_masked_images_again(tmp_path):
    """The store keeps `masked` with its robot: the robot rebuilt from its attrs (as the levels render targets)
    draws the stored masked images again (within 1 of 255 levels: another GL context may round differently)."""
    path = generate(DatagenConfig(robot=str(planar2_with(tmp_path, {**ON_LINK1, "masked": True})), n=8, shard_size=8,
                                  seed=0, out=tmp_path / "s.zarr"), progress=False)
    root = zarr.open_group(path, mode="r")
    with Robot.from_attrs(dict(root.attrs)) as robot:
        again = robot.render(np.asarray(root["q"][:]), modality="image_wrist").astype(int)
    assert np.abs(again - np.asarray(root["image_wrist"][:])).max() <= 1
    assert robot.record.cameras[0]["masked"] is True


def test_mount_camera_frames_the_bodies_beyond_the_link(tmp_path):
    """Placed for the elbow, the camera rides on link1, keeps the ee in its image in every sampled pose, and sees the
    elbow change more pixels per degree than the fixed camera does."""
    record = read_record(planar2_with(tmp_path))
    box = np.array(record.workspaces["camera"])
    with Robot.load(record) as robot:
        camera = mount_camera(robot, "elbow", box)
        fixed = observability(robot, box)
    assert camera["name"] == MOUNTED and camera["body"] == "link1"
    with Robot.load(dataclasses.replace(record, cameras=(camera,))) as robot:
        model, data, cam = robot.model, mujoco.MjData(robot.model), robot.cameras["image_mounted"]
        for q in np.random.default_rng(1).uniform(box[:, 0], box[:, 1], (64, 2)):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            mujoco.mj_camlight(model, data)
            view = FixedCamera.from_mujoco(data.cam_xpos[cam], data.cam_xmat[cam], model.cam_fovy[cam],
                                           robot.image_size)
            assert view.sees(data.site_xpos[model.site(robot.ee_site).id][None])[0], q
        mounted = observability(robot, box, modality="image_mounted")
    assert mounted.joints[1].px_per_deg > fixed.joints[1].px_per_deg
    chosen, seen = choose_mount(record, box, [fixed])
    assert chosen == camera and seen.joints == mounted.joints          # the only joint on a moving link: the elbow


def test_robot_camera_mount_writes_the_record(tmp_path, capsys):
    """One camera per --mount value, mounted, mounted2, ...; each replaces the record's camera of its name."""
    path = planar2_with(tmp_path, {**ON_LINK1, "name": MOUNTED}, {**ON_LINK1, "name": "mounted2"}, size=(24, 24))
    assert run_camera(RobotCameraArgs(record=path, mount=("auto", "elbow"))) == 0
    record = read_record(path)
    assert record.further_cameras == (MOUNTED, "mounted2") and [c["body"] for c in record.cameras] == ["link1"] * 2
    assert record.cameras[0] == record.cameras[1] | {"name": MOUNTED}      # the elbow's link, twice: the same pose
    out = capsys.readouterr().out
    assert "mounted camera 'mounted' (image_mounted) on link 'link1'" in out and "(image_mounted2)" in out


def test_a_masked_camera_sees_the_joints_beyond_its_link_alone(tmp_path):
    """`robot camera --mount elbow --masked`: the camera on link1 draws link1 and link2 only, lit by its headlight, so
    its image does not change with the shoulder (within 1 of 255 levels: the GL pipeline rounds the world's float32
    transforms differently at each shoulder angle) and does change with the elbow; unmasked, the world's light shades
    link2 by the shoulder too."""
    path = planar2_with(tmp_path, size=(32, 32))
    assert run_camera(RobotCameraArgs(record=path, mount=("elbow",), masked=True)) == 0
    masked = read_record(path)
    assert masked.cameras[0]["masked"] is True and masked.cameras[0]["body"] == "link1"
    elbows = np.random.default_rng(0).uniform(-2.0, 2.0, 8)
    poses = [np.stack([np.full(8, shoulder), elbows], axis=1) for shoulder in (-1.0, 0.3, 1.2)]
    with Robot.load(masked) as robot:
        images = [robot.render(q, modality="image_mounted").astype(int) for q in poses]
    for other in images[1:]:
        assert np.abs(other - images[0]).max() <= 1
    assert np.abs(np.diff(images[0], axis=0)).max() > 50                         # the elbow moves link2 in view
    unmasked = dataclasses.replace(masked, cameras=({k: v for k, v in masked.cameras[0].items() if k != "masked"},))
    with Robot.load(unmasked) as robot:
        lit = [robot.render(q, modality="image_mounted").astype(int) for q in poses]
    assert np.abs(lit[1] - lit[0]).max() > 1


def test_a_second_auto_places_for_what_the_first_left_weakest():
    """On the shipped panda (masked cameras): given the first mounted camera's view, `choose_mount` puts the second on
    another link, and the weakest joint's best share over the cameras rises."""
    shipped = read_record(shipped_dir() / "panda.toml")
    record = dataclasses.replace(shipped, model=str(shipped.model_path), reaching={})
    box = np.array(record.workspaces["camera"])
    with Robot.load(record) as robot:
        fixed = observability(robot, box)
    first, first_seen = choose_mount(record, box, [fixed], MOUNTED, masked=True)
    second, second_seen = choose_mount(dataclasses.replace(record, cameras=(first,)), box, [fixed, first_seen],
                                       "mounted2", masked=True)

    def weakest(views):
        return min(max(v.joints[i].share_per_deg for v in views) for i, j in enumerate(fixed.joints) if not j.on_axis)

    assert second["body"] != first["body"] and second["masked"]
    assert weakest([fixed, first_seen, second_seen]) > weakest([fixed, first_seen])


def test_a_shorter_mount_leaves_no_earlier_mounted_camera(tmp_path):
    """--mount sets the record's mounted cameras: after a cascade of three, `--mount elbow` leaves one, and a further
    camera of another name stays."""
    side = {**ON_LINK1, "name": "side"}
    cascade = [{**ON_LINK1, "name": n} for n in (MOUNTED, "mounted2", "mounted3")]
    path = planar2_with(tmp_path, side, *cascade, size=(24, 24))
    assert run_camera(RobotCameraArgs(record=path, mount=("elbow",))) == 0
    assert read_record(path).further_cameras == ("side", MOUNTED)


def test_a_joint_on_a_fixed_link_has_no_link_to_mount_on(tmp_path):
    path = planar2_with(tmp_path)
    before = path.read_bytes()
    with pytest.raises(ValueError, match="joint 'shoulder' of mounted2 must be a joint after the first moving link"):
        run_camera(RobotCameraArgs(record=path, mount=("auto", "shoulder")))
    with pytest.raises(ValueError, match="joint to mount a camera for must be one of"):
        run_camera(RobotCameraArgs(record=path, mount=("knee",)))
    assert path.read_bytes() == before                                          # nothing written


@pytest.mark.parametrize("camera, message", [
    ({**ON_LINK1, "body": 3}, "record camera 'wrist' body must be the name of a body of the model"),
    ({**ON_LINK1, "lens": "wide"},
     r"record camera 'wrist' must be keys among \['name', 'pos', 'xyaxes', 'fovy', 'body', 'masked'\]"),
    ({**ON_LINK1, "masked": "yes"}, "record camera 'wrist' masked must be true or false. Got 'yes'"),
    ({**{k: v for k, v in ON_LINK1.items() if k != "body"}, "masked": True},
     r"record camera 'wrist' masked must be on a camera riding on a link \(with `body`\)"),
])
def test_a_bad_mounted_camera_is_refused_when_read(tmp_path, camera, message):
    values = read_record(planar2_with(tmp_path)).to_toml_dict() | {"cameras": [camera]}
    with pytest.raises(ValueError, match=message):
        record_from_dict(values, tmp_path)


def test_the_records_own_camera_stays_fixed_in_the_world(tmp_path):
    values = read_record(planar2_with(tmp_path)).to_toml_dict()
    with pytest.raises(ValueError, match=r"\[camera\] of .* must be keys among"):
        record_from_dict(values | {"camera": {k: v for k, v in ON_LINK1.items() if k != "name"} | {"name": "auto"}},
                         tmp_path)
    xml = (shipped_dir() / "planar2.xml").read_text().replace(   # a camera of the file, riding on link1
        '<joint name="shoulder"', '<camera name="ride" pos="0.3 0 0.5"/><joint name="shoulder"')
    (tmp_path / "ride.xml").write_text(xml)
    ride = dataclasses.replace(read_record(shipped_dir() / "planar2.toml"), name="ride", model="ride.xml",
                               camera={"name": "ride"}, reaching={}, base=tmp_path)
    with pytest.raises(ValueError, match="camera 'ride' of ride must be a camera fixed in the world"):
        Robot.load(ride)


def test_a_mounted_camera_on_a_body_the_file_lacks_is_the_house_error(tmp_path):
    record = read_record(planar2_with(tmp_path, {**ON_LINK1, "body": "forearm"}))
    with pytest.raises(ValueError, match=r"camera 'wrist' body must be one of the model's bodies \['link1', 'link2'\]"):
        Robot.load(record)


def test_a_camera_on_the_last_link_sees_nothing_move(tmp_path):
    """The arm's share of a mounted camera's image counts the bodies that move relative to it: looking down at the
    marker from above link2, nothing does."""
    above = {"name": "tip", "pos": [0.25, 0.0, 0.3], "xyaxes": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "fovy": 20.0,
             "body": "link2"}
    with Robot.load(planar2_with(tmp_path, above)) as robot:
        seen = observability(robot, modality="image_tip")
        assert robot.render(np.zeros((1, 2)), modality="image_tip").any()         # the marker is in view
    assert seen.arm_fraction == 0.0 and seen.joints[1].px_per_deg == 0.0
