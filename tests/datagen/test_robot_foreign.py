"""Arms the project did not write, from packages pinned in the test extra (nothing downloaded at run time):
dm_control's Kinova Jaco (MJCF, STL meshes) and example-robot-data's URDFs: TALOS's left arm (7 of the humanoid's
46 joints, the others held; STL meshes) and the UR5 (Collada visuals: the house error, or the collision geometry)."""

import dataclasses
import importlib.metadata
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bodyschema.cli import main
from bodyschema.datagen.body.build import build_model, read_source
from bodyschema.datagen.body.infer import SAG_RAD, ee_samples, infer_record, place_camera, view_fraction
from bodyschema.datagen.body.record import RobotRecord, write_record
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.validate import validate_store


def _package_file(dist: str, relative: str) -> Path:
    try:
        path = Path(importlib.metadata.distribution(dist).locate_file(relative))
    except importlib.metadata.PackageNotFoundError:
        pytest.skip(f"{dist} is not installed (pip install -e '.[test]')")
    return path


@pytest.fixture(scope="module")
def jaco_file():
    return _package_file("dm_control", "dm_control/third_party/kinova/jaco_arm.xml")


@pytest.fixture(scope="module")
def robots_dir():
    return _package_file("example-robot-data", "cmeel.prefix/share/example-robot-data/robots")


@pytest.fixture(scope="module")
def jaco(jaco_file):
    with Robot.load(infer_record(jaco_file)) as robot:
        yield robot


HOLD = {"torso_2_joint": 0.2, "arm_right_4_joint": -1.0}
ARM = tuple(f"arm_left_{i}_joint" for i in range(1, 8))


@pytest.fixture(scope="module")
def talos_record(robots_dir, tmp_path_factory):
    """TALOS's left arm: a record written by hand, as a user would, its camera placed from sampled FK."""
    model = robots_dir / "talos_data/robots/talos_full_v2.urdf"
    box = ((-1.0, 0.7), (0.1, 2.0), (-1.5, 1.5), (-2.0, -0.1), (-1.5, 1.5), (-1.0, 1.0), (-0.5, 0.5))
    record = RobotRecord(name="talos_left_arm", model=str(model), joints=ARM, hold=HOLD, visual="collision",
                         ee={"body": "arm_left_7_link", "offset": [0.0, 0.0, -0.1]}, image_size=(48, 48),
                         workspaces={"full": box, "camera": box}, base=tmp_path_factory.mktemp("talos"),
                         camera={"name": "auto", "pos": [2.0, 0.0, 1.0], "xyaxes": [0, 1, 0, 0, 0, 1], "fovy": 45})
    with Robot.load(record) as robot:
        camera = place_camera(ee_samples(robot, np.array(box)), record.image_size)
    record = dataclasses.replace(record, camera=camera)
    write_record(record, record.base / "talos_left_arm.toml")
    return record


@pytest.fixture(scope="module")
def talos(talos_record):
    with Robot.load(talos_record) as robot:
        yield robot


def test_jaco_loads_from_its_mjcf_with_meshes_and_its_camera_sees_the_hand(jaco):
    assert jaco.dq == 6 and jaco.source.meshes and jaco.ee_site == "wristsite"
    assert view_fraction(jaco, jaco.sampling_ranges) > 0.9


def test_talos_left_arm_is_a_joint_subset_whose_fk_equals_the_whole_humanoid(talos, talos_record):
    assert talos.joint_names == ARM and talos.model.nq == 7
    spec, _ = read_source(talos_record)                                   # the whole humanoid, every joint free
    full = spec.compile()
    data = mujoco.MjData(full)
    q = np.random.default_rng(0).uniform(talos.sampling_ranges[:, 0], talos.sampling_ranges[:, 1], (20, 7))
    hand = full.body("arm_left_7_link").id
    for q_i, xyz in zip(q, talos.fk(q)):
        data.qpos[:] = full.qpos0
        for name, value in [*zip(ARM, q_i), *HOLD.items()]:
            data.qpos[full.joint(name).qposadr[0]] = value
        mujoco.mj_kinematics(full, data)
        expected = data.xpos[hand] + data.xmat[hand].reshape(3, 3) @ np.array([0.0, 0.0, -0.1])
        np.testing.assert_allclose(xyz, expected, atol=1e-9)


@pytest.mark.parametrize("arm", ["jaco", "talos"])
def test_jacobian_matches_finite_differences_and_the_camera_renders_the_arm(arm, request):
    robot = request.getfixturevalue(arm)
    q = np.random.default_rng(1).uniform(robot.sampling_ranges[:, 0], robot.sampling_ranges[:, 1], (4, robot.dq))
    jac, h = robot.jacobian(q), 1e-6
    for j in range(robot.dq):
        step = np.zeros(robot.dq)
        step[j] = h
        numeric = (robot.fk(q + step, check=False) - robot.fk(q - step, check=False)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, j], numeric, atol=1e-6)
    images = robot.render(q)
    assert images.shape == (4, *robot.image_size) and all(image.std() > 0 for image in images)


def test_ur5_collada_visuals_are_the_house_error_unless_the_collision_geometry_is_asked_for(robots_dir, tmp_path,
                                                                                          capsys):
    urdf = robots_dir / "ur_description/urdf/ur5_robot.urdf"
    record = tmp_path / "ur5.toml"
    assert main(["robot", "init", str(urdf), "--out", str(record)]) == 2
    err = capsys.readouterr().err
    assert "visual/base.dae must be a format MuJoCo loads" in err and "--visual collision" in err
    assert not record.exists()
    assert main(["robot", "init", str(urdf), "--out", str(record), "--visual", "collision"]) == 0
    store = generate(DatagenConfig(robot=str(record), n=6, shard_size=6, out=tmp_path / "ur5.zarr"), progress=False)
    assert validate_store(store) == []


def test_robot_show_and_datagen_with_images_on_talos(talos_record, tmp_path, capsys):
    path = talos_record.base / "talos_left_arm.toml"
    assert main(["robot", "show", str(path), "--n", "4", "--out", str(tmp_path / "sheet.png")]) == 0
    out = capsys.readouterr().out
    assert "arm_left_1_joint" in out and "ee in view" in out and (tmp_path / "sheet.png").is_file()
    store = generate(DatagenConfig(robot=str(path), n=6, shard_size=6, out=tmp_path / "talos.zarr"), progress=False)
    assert validate_store(store) == []


def _servo_episodes(record: RobotRecord, episodes: int = 8, seconds: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Per episode: the largest joint error after `seconds` of position servos to a random target, and whether any
    contact occurred (targets and starts uniform in the record's full box, seed 0)."""
    model = build_model(record).model
    box = np.array(record.workspaces["full"])
    rng = np.random.default_rng(0)
    errors, touched = [], []
    for _ in range(episodes):
        data = mujoco.MjData(model)
        data.qpos[:], data.ctrl[:] = rng.uniform(box[:, 0], box[:, 1], (2, model.nq))
        contact = False
        for _ in range(int(seconds / model.opt.timestep)):
            mujoco.mj_step(model, data)
            contact |= data.ncon > 0
        errors.append(np.abs(data.qpos - data.ctrl).max())
        touched.append(contact)
    return np.array(errors), np.array(touched)


def test_ur5_record_drops_self_collisions_so_its_servos_reach_what_its_collision_meshes_jammed(robots_dir,
                                                                                              tmp_path):
    urdf = robots_dir / "ur_description/urdf/ur5_robot.urdf"
    record = infer_record(urdf, visual="collision")
    assert record.collisions == "none"
    # moves across ±π: the stiff servos' damping at the URDF's effort limits caps their speed (≈ effort / kv)
    errors, touched = _servo_episodes(record, seconds=4.0)
    assert not touched.any() and errors.max() < 4 * SAG_RAD    # settled to within a few sag bounds
    _, touched = _servo_episodes(dataclasses.replace(record, collisions="model"))
    assert touched.any()                                    # the file's own collision meshes do touch
