"""Robot records (TOML) with a value of the wrong type or out of range (issue 32 items 10, 14-16): the house line
naming the key, exit 2, no traceback, nothing written, also through `gymnasium.make(..., robot=record)`; and a
per-robot Gymnasium id refuses another robot."""

from __future__ import annotations

import pytest

from bodyschema.datagen.body.record import read_record, shipped_dir
from tests.test_cli_fuzz import run_and_check

GOOD = """name = "{name}"
model = "{model}"
image_size = [32, 32]
{top}
[ee]
{ee}

[camera]
name = "eye"

[actuators]
kind = "model"

[reaching]
models = ["ee_xyz", "joints"]
control_hz = 50.0
duration_s = {duration}

[pd]
kp = [1.0, 1.0]
kd = {kd}

[workspaces]
{workspaces}
"""
DEFAULTS = {"name": "arm", "top": "", "ee": 'site = "ee"', "duration": "3.0", "kd": "[0.1, 0.1]",
            "workspaces": "full = [[-2.5, 2.5], [-2.5, 2.5]]\ncamera = [[-2.5, 2.5], [-2.5, 2.5]]"}
RECORDS = {   # file stem → the one change to a good record of the shipped planar2.xml
    "good": {},
    "hold5": {"top": "hold = 5"},
    "joints5": {"top": "joints = 5"},
    "joints_string": {"top": 'joints = "shoulder"'},
    "workspace_flat": {"workspaces": "full = [1.0, 2.0]\ncamera = [[-2.5, 2.5], [-2.5, 2.5]]"},
    "duration_negative": {"duration": "-1"},
    "mesh_dir5": {"top": "mesh_dir = 5"},
    "kd_short": {"kd": "[0.1]"},
    "ee_world": {"ee": 'body = "world"'},
    "ee_fixed_site": {"ee": 'site = "fixed"', "model": "fixed_site.xml"},
    "name_dotdot": {"name": ".."},
    "name_script": {"name": "a\\nb<script>"},
    "name_shipped": {"name": "planar2"},      # a copy's store would be checked against the shipped planar2
}
SHOW = "robot show {W}/%s.toml --n 1 --out {W}/s.png"
GEN = "datagen --robot {W}/%s.toml --n 4 --no-images --out {W}/o.zarr"
REACH = "evaluate reaching --robot {W}/%s.toml --trials 1 --out {W}/r"   # [reaching] is the benchmark's to check
CASES = [
    ("record-hold-a-number", GEN % "hold5"),
    ("record-joints-a-number", GEN % "joints5"),
    ("record-joints-a-string", GEN % "joints_string"),
    ("record-workspace-not-boxes", GEN % "workspace_flat"),
    ("record-reaching-duration-negative", REACH % "duration_negative"),
    ("record-mesh-dir-a-number", SHOW % "mesh_dir5"),
    ("record-pd-kd-one-gain-for-two-joints", SHOW % "kd_short"),
    ("record-ee-on-the-world", SHOW % "ee_world"),
    ("record-ee-site-on-the-world", SHOW % "ee_fixed_site"),
    ("record-name-dotdot", SHOW % "name_dotdot"),
    ("record-name-dotdot-datagen", GEN % "name_dotdot"),
    ("record-name-with-newline-and-markup", GEN % "name_script"),
    ("record-name-a-shipped-robots", GEN % "name_shipped"),
]
WORDS = {
    "record-hold-a-number": "`hold` of",
    "record-joints-a-number": "record `joints` must be a list of distinct joint names",
    "record-joints-a-string": "record `joints` must be a list of distinct joint names, e.g. "
                              "[\"shoulder\", \"elbow\"]. Got 'shoulder'",
    "record-workspace-not-boxes": "record workspace 'full' must be",
    "record-reaching-duration-negative": "record [reaching] duration_s must be a finite number > 0",
    "record-mesh-dir-a-number": "record `mesh_dir` must be a folder path",
    "record-pd-kd-one-gain-for-two-joints": "record [pd] kp and kd",
    "record-ee-on-the-world": "record [ee] body must be a body the joints move",
    "record-ee-site-on-the-world": "the ee of robot 'arm' must be moved by the chosen joints",
    "record-name-dotdot": "record `name` must be",
    "record-name-dotdot-datagen": "record `name` must be",
    "record-name-with-newline-and-markup": "record `name` must be",
    "record-name-a-shipped-robots": "must be not a shipped robot's name",
}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("robot_records"))


def make_world(w):
    """Records of the shipped planar2.xml, each wrong in one way (and one good); planar2 with a site on the world."""
    (w / "fixed_site.xml").write_text((shipped_dir() / "planar2.xml").read_text().replace(
        "<worldbody>", '<worldbody><site name="fixed" pos="0 0 0.1"/>', 1))
    for stem, change in RECORDS.items():
        values = {**DEFAULTS, "model": str(shipped_dir() / "planar2.xml"), **change}
        (w / f"{stem}.toml").write_text(GOOD.format(**values))
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_record_is_a_clear_error(case_id, command, in_world, capsys):
    err = run_and_check(case_id, command, in_world, capsys)
    assert WORDS[case_id] in err, err


def test_the_good_record_of_the_world_reads(world):
    assert read_record(world / "good.toml").joints == ()


@pytest.mark.parametrize("stem", ["hold5", "joints5", "workspace_flat", "duration_negative", "name_dotdot"])
def test_a_bad_record_through_gymnasium_is_the_house_error(stem, world):
    gymnasium = pytest.importorskip("gymnasium")
    from bodyschema.envs.registration import GENERIC_ID

    with pytest.raises(ValueError, match=" must be "):
        gymnasium.make(GENERIC_ID, robot=str(world / f"{stem}.toml"))


def test_a_robot_id_refuses_another_robot():
    gymnasium = pytest.importorskip("gymnasium")
    from bodyschema.envs.registration import GENERIC_ID, env_id

    with pytest.raises(ValueError, match=r"robot of bodyschema/Reach-nao_arm-v0 must be 'nao_arm'.*Reach-v0"):
        gymnasium.make(env_id("nao_arm"), robot="panda")
    env = gymnasium.make(env_id("planar2"), robot="planar2")            # naming its own robot is fine
    assert env.unwrapped.robot.name == "planar2"
    assert gymnasium.make(GENERIC_ID, robot="planar2").unwrapped.robot.name == "planar2"


def test_a_file_named_like_a_shipped_robot_gets_a_name_of_its_own(tmp_path):
    """example-robot-data's Panda URDF says <robot name="panda">: `robot init` must not call it the shipped panda,
    whose model its stores would be validated against (they failed `validate` after a whole datagen run)."""
    from bodyschema.datagen.body.infer import file_name

    urdf = '<robot name="panda"><link name="base"/></robot>'
    assert file_name(urdf, tmp_path / "panda.urdf") == "panda_urdf"
    assert file_name(urdf.replace("panda", "my_panda"), tmp_path / "panda.urdf") == "my_panda"
