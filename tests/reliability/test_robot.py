"""Bad robot input at the CLI (issue 20's list), beside tests/test_cli_fuzz.py and with its harness: not MJCF/URDF,
no such site/body/camera (what exists is listed), a chosen joint that is not a hinge, a camera that sees the ee in
under 20 % of poses, an unsupported mesh. Each case: the house line, exit 2, no traceback, nothing written."""

import pytest

from bodyschema.datagen.body.record import dumps_toml
from tests.test_cli_fuzz import run_and_check, run_in_process

ARM = """<mujoco model="arm"><compiler angle="radian"/><worldbody>
  <camera name="away" pos="0 0 2" xyaxes="1 0 0 0 -1 0"/>
  <body name="base"><joint name="rail" type="slide" axis="1 0 0" range="-0.1 0.1"/>
    <geom type="box" size="0.05 0.05 0.02" mass="1"/>
    <body name="link" pos="0 0 0.05"><joint name="hinge" axis="0 1 0" range="-1 1"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.02" mass="0.3"/><site name="tip" pos="0 0 0.3"/>
    </body></body></worldbody></mujoco>"""
BOX = {"full": [[-1.0, 1.0]], "camera": [[-1.0, 1.0]]}
RECORDS = {   # name → changes to a record of arm.xml that is good otherwise
    "badsite": {"ee": {"site": "hand"}},
    "badbody": {"ee": {"body": "palm", "offset": [0.0, 0.0, 0.1]}},
    "badcam": {"camera": {"name": "top"}},
    "slide": {"joints": ["rail", "hinge"], "workspaces": {"full": [[-0.1, 0.1], [-1.0, 1.0]],
                                                           "camera": [[-0.1, 0.1], [-1.0, 1.0]]}},
    "blind": {"camera": {"name": "away"}},                                # looks up, away from the arm
}
URDF = """<robot name="dae"><link name="base"/><link name="arm"><visual><geometry><mesh filename="arm.dae"/>
  </geometry></visual></link><joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
  <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""

CASES = [
    ("datagen-not-a-model", "datagen --robot {W}/arm.sdf --n 4 --out {W}/o.zarr"),
    ("datagen-missing-model", "datagen --robot {W}/nothere.xml --n 4 --out {W}/o.zarr"),
    ("datagen-no-such-site", "datagen --robot {W}/badsite.toml --n 4 --out {W}/o.zarr"),
    ("datagen-no-such-body", "datagen --robot {W}/badbody.toml --n 4 --out {W}/o.zarr"),
    ("datagen-no-such-camera", "datagen --robot {W}/badcam.toml --n 4 --out {W}/o.zarr"),
    ("datagen-slide-joint", "datagen --robot {W}/slide.toml --n 4 --no-images --out {W}/o.zarr"),
    ("datagen-blind-camera", "datagen --robot {W}/blind.toml --n 4 --out {W}/o.zarr"),
    ("datagen-dae-mesh", "datagen --robot {W}/dae.urdf --n 4 --out {W}/o.zarr"),
    ("show-blind-camera", "robot show {W}/blind.toml --out {W}/s.png"),
    ("show-no-such-site", "robot show {W}/badsite.toml --out {W}/s.png"),
    ("show-unknown-name", "robot show pr2"),
    ("init-not-a-model", "robot init {W}/arm.sdf"),
    ("init-dae-mesh", "robot init {W}/dae.urdf"),
    ("init-existing-record", "robot init {W}/arm.xml --out {W}/badsite.toml"),
    ("reaching-not-a-model", "evaluate reaching --robot {W}/arm.sdf --trials 1 --no-mlflow"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("robot_world"))


def make_world(w):
    """A one-hinge arm, files that are not robots, and records each wrong in one way."""
    (w / "arm.xml").write_text(ARM)
    (w / "arm.sdf").write_text("<sdf/>")
    (w / "dae.urdf").write_text(URDF)
    (w / "arm.dae").write_text("<COLLADA/>")
    for name, change in RECORDS.items():
        values = {"name": name, "model": "arm.xml", "joints": ["hinge"], "image_size": [32, 32],
                  "ee": {"site": "tip"}, "camera": {"name": "away"}, "workspaces": BOX,
                  "actuators": {"kind": "servos", "kp": [1.0], "kv": [0.1]}, **change}
        if "rail" in values["joints"]:
            values["actuators"] = {"kind": "model"}
        (w / f"{name}.toml").write_text(dumps_toml(values))
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_robot_input_is_a_clear_error(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)


@pytest.mark.parametrize("case_id, words", [
    ("datagen-no-such-site", "one of the model's sites ['tip']"),
    ("datagen-no-such-body", "'base', 'link'"),
    ("datagen-no-such-camera", "cameras ['away']"),
    ("datagen-slide-joint", "must be a hinge. Got 'a slide joint'"),
    ("datagen-blind-camera", "at least 20% of the sampled poses. Got '0.0%'"),
    ("datagen-dae-mesh", "arm.dae must be a format MuJoCo loads"),
])
def test_the_message_lists_what_exists_or_the_figure(case_id, words, in_world, capsys):
    _, err = run_in_process(dict(CASES)[case_id].format(W=in_world).split(), capsys)
    assert words in err, err
