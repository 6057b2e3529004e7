"""Robot files as people have them (issue 33 item 6): meshes not on disk (`--visual primitives`), a humanoid whose
arm `robot init` must find (not its fingers), the file's own robot name, and images rendered only as detailed as
they need. Arms from example-robot-data (test extra; nothing downloaded): TALOS copied without its meshes, and
others' URDFs read with primitives (no mesh read, so quick)."""

import importlib.metadata
import re
import shutil
from pathlib import Path

import cv2
import mujoco
import numpy as np
import pytest
import zarr

from bodyschema.cli import main
from bodyschema.datagen.body.attrs import MODEL_KEY
from bodyschema.datagen.body.infer import infer_record
from bodyschema.datagen.body.record import read_record
from bodyschema.datagen.body.record_checks import NAME_PATTERN
from bodyschema.datagen.body.render_scope import HIDDEN_GROUP, render_model
from bodyschema.datagen.body.robot import Robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.validate import validate_store

LEFT_ARM = tuple(f"arm_left_{i}_joint" for i in range(1, 8))


@pytest.fixture(scope="module")
def robots_dir():
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


@pytest.fixture(scope="module")
def bare_talos(robots_dir, tmp_path_factory) -> Path:
    """TALOS's URDF alone in a folder, as a user has it: its package:// meshes are not on disk."""
    folder = tmp_path_factory.mktemp("bare")
    return Path(shutil.copy(robots_dir / "talos_data/robots/talos_full_v2.urdf", folder / "model.urdf"))


@pytest.fixture(scope="module")
def talos_record(bare_talos) -> Path:
    out = bare_talos.parent / "talos.toml"
    assert main(["robot", "init", str(bare_talos), "--visual", "primitives", "--out", str(out)]) == 0
    return out


def test_missing_meshes_are_the_house_error_naming_the_primitive_fallback(bare_talos, tmp_path, capsys):
    for visual in ("mesh", "collision"):
        assert main(["robot", "init", str(bare_talos), "--visual", visual, "--out", str(tmp_path / "r.toml")]) == 2
        err = capsys.readouterr().err.strip()
        assert "must be found in a folder named" in err and "--visual primitives" in err and "\n" not in err
    assert not (tmp_path / "r.toml").exists()


def test_init_with_primitives_picks_the_left_arm_names_the_robot_from_the_file_and_says_what_was_replaced(
        talos_record):
    record = read_record(talos_record)
    assert record.name == "talos"                                  # <robot name="talos">, not the stem "model"
    assert record.joints == LEFT_ARM                               # no torso, no finger, no mimic joint
    assert record.ee == {"body": "gripper_left_base_link", "offset": [0.0, 0.0, 0.0]}
    assert record.visual == "primitives"
    header = "".join(line for line in talos_record.read_text().splitlines(True) if line.startswith("#"))
    assert re.search(r"visual = \"primitives\": \d+ links drawn as capsules/boxes instead of \d+ meshes", header)
    assert "#   arm_left_4_link: package:///example-robot-data/robots/talos_data/meshes/arm/arm_4.stl\n" in header


def test_primitives_render_the_arm_and_it_moves_in_the_image(talos_record):
    with Robot.load(read_record(talos_record)) as robot:
        assert not robot.source.meshes and "arm_left_4_link" in robot.source.replaced
        q = np.mean(robot.sampling_ranges, axis=1)[None].repeat(2, axis=0)
        q[1, LEFT_ARM.index("arm_left_4_joint")] = robot.sampling_ranges[3, 0]     # bend the elbow
        images = robot.render(q)
    silhouette = images > 0                                        # the background renders black
    assert 0.01 < silhouette[0].mean() < 0.6
    changed = np.abs(images[0].astype(int) - images[1]) > 8
    assert changed.mean() > 0.005                                  # the elbow moved pixels, not only noise


def test_datagen_writes_a_valid_store_with_primitives_and_records_what_was_replaced(talos_record, tmp_path):
    store = generate(DatagenConfig(robot=str(talos_record), n=6, shard_size=6, out=tmp_path / "t.zarr"),
                     progress=False)
    assert validate_store(store) == []
    attrs = zarr.open_group(store, mode="r").attrs.asdict()
    assert "arm_left_4_link" in attrs[MODEL_KEY]["replaced"] and attrs[MODEL_KEY]["meshes"] == {}


@pytest.mark.parametrize("file, ee, joints", [
    ("ur_description/urdf/ur5_robot.urdf", "ee_link", ("shoulder_pan_joint", "wrist_3_joint")),
    ("panda_description/urdf/panda.urdf", "panda_hand_tcp", ("panda_joint1", "panda_joint7")),
    ("baxter_description/urdf/baxter.urdf", "right_gripper", ("right_s0", "right_w2")),
    ("icub_description/robots/icub_reduced.urdf", "l_gripper", ("l_shoulder_pitch", "l_wrist_yaw")),
    ("so_arm_description/urdf/so100.urdf", "gripper", ("shoulder_pan", "wrist_roll")),
    ("romeo_description/urdf/romeo.urdf", "l_gripper", ("LShoulderPitch", "LWristPitch")),
])
def test_the_inferred_arm_ends_in_a_hand_without_fingers_torso_or_mimic_joints(robots_dir, file, ee, joints):
    record = infer_record(robots_dir / file, visual="primitives")
    assert record.ee["body"] == ee and (record.joints[0], record.joints[-1]) == joints
    assert not any(re.search("finger|thumb|gripper|torso|head|leg", j, re.I) for j in record.joints)
    assert NAME_PATTERN.fullmatch(record.name)


def test_ee_and_joints_given_are_honoured(bare_talos):
    right = infer_record(bare_talos, visual="primitives", ee="arm_right_7_link")
    assert right.joints == tuple(j.replace("left", "right") for j in LEFT_ARM)
    assert right.ee == {"body": "arm_right_7_link", "offset": [0.0, 0.0, 0.0]}
    upper = infer_record(bare_talos, visual="primitives", joints=LEFT_ARM[:4])
    assert upper.joints == LEFT_ARM[:4] and upper.ee["body"] == "arm_left_4_link"
    for kwargs, where in (({"ee": "no_such_body"}, "--ee"), ({"joints": ("arm_left_1_joint", "nope")}, "--joints")):
        with pytest.raises(ValueError, match=f"^{where} must be"):
            infer_record(bare_talos, visual="primitives", **kwargs)


def test_the_robot_name_comes_from_the_file_made_safe_else_the_stem(bare_talos, tmp_path):
    text = bare_talos.read_text()
    (tmp_path / "a.urdf").write_text(text.replace('<robot name="talos"', '<robot name="../my robot:v2"', 1))
    (tmp_path / "b.urdf").write_text(re.sub(r'<robot name="talos"', "<robot", text, count=1))
    named = infer_record(tmp_path / "a.urdf", visual="primitives").name
    assert NAME_PATTERN.fullmatch(named) and "my_robot_v2" in named and "/" not in named
    assert infer_record(tmp_path / "b.urdf", visual="primitives").name == "b"


def test_the_render_copy_of_a_shipped_arm_draws_the_same_image():
    with Robot.load("nao_arm") as robot:
        q = np.random.default_rng(0).uniform(robot.sampling_ranges[:, 0], robot.sampling_ranges[:, 1], (4, 4))
        images = robot.render(q)
        plain = mujoco.Renderer(robot.model, *robot.image_size)
        data = mujoco.MjData(robot.model)
        for q_i, image in zip(q, images):
            data.qpos[:] = q_i
            mujoco.mj_kinematics(robot.model, data)
            mujoco.mj_camlight(robot.model, data)
            plain.update_scene(data, robot.camera_name)
            rgb = plain.render()
            np.testing.assert_array_equal(image, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
        plain.close()


def test_the_render_copy_of_a_file_arm_casts_no_shadow_and_hides_only_held_geoms(talos_record):
    with Robot.load(read_record(talos_record)) as robot:
        model = robot.model
        scene = render_model(model, robot._cam, robot.image_size, None, simplify=True)
        assert model.vis.quality.shadowsize == 4096 and scene.vis.quality.shadowsize == 0
        assert not scene.light_castshadow.any() and model.nlight >= 1
        hidden = scene.geom_group == HIDDEN_GROUP
        assert not hidden[model.body_weldid[model.geom_bodyid] != 0].any()       # no geom of the arm
