"""Robot files that reach out of their folder, block, or ask MuJoCo for huge buffers (issue 32 items 5-9): each is the
house line naming the file, exit 2, no traceback, nothing written, and refused before MuJoCo reads or allocates it.
Cases that used to hang or eat the machine's memory run as real processes with a timeout and a memory limit
(CASES_IN_SUBPROCESS), so a regression fails instead of stalling the suite."""

from __future__ import annotations

import os
import resource
import struct
import subprocess
import sys

import pytest

from bodyschema.datagen.body import model_files
from bodyschema.datagen.body.build import read_source
from bodyschema.datagen.body.infer import infer_record
from tests.reliability.test_robot import ARM
from tests.test_cli_fuzz import check_clear_failure, run_and_check, snapshot

GEN = "datagen --robot {W}/%s --n 4 --no-images --out {W}/o.zarr"
# A binary STL of 300 small triangles, ~15 kB (MuJoCo reads binary STL only), larger than any URDF written here.
STL = b"\0" * 80 + struct.pack("<I", 300) + b"".join(
    struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 0.02, 0, i * 1e-4, 0, 0.02, 0, 0) for i in range(300))
URDF = """<robot name="r"><link name="base"/><link name="arm"><inertial><mass value="0.1"/>
  <inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>{visuals}</link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
  <limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""
VISUAL = '<visual><origin xyz="0.1 0 0"/><geometry><mesh filename="{file}"/></geometry></visual>'
CYCLIC = """<robot name="c"><link name="a"/><link name="b"/>
<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
  <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="b"/><child link="a"/><axis xyz="0 0 1"/>
  <limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""

CASES = [
    ("include-absolute-path", GEN % "passwd.xml"),
    ("include-dotdot-out-of-the-folder", GEN % "sub/dotdot.xml"),
    ("include-missing", GEN % "missing_inc.xml"),
    ("include-missing-show", "robot show {W}/missing_inc.xml --out {W}/s.png"),
    ("model-not-utf8", GEN % "latin1.xml"),
    ("model-doctype-entity", GEN % "entity.xml"),
    ("offscreen-30000", GEN % "offwidth.xml"),
    ("offscreen-30000-show", "robot show {W}/offwidth.xml --out {W}/s.png"),
    ("mesh-degenerate", GEN % "degenerate.xml"),
    ("urdf-cyclic", GEN % "u/cyclic.urdf"),
    ("urdf-absolute-mesh", GEN % "u/absolute.urdf"),
    ("urdf-dotdot-mesh", GEN % "u/dotdot.urdf"),
    ("urdf-package-walks-up", GEN % "u/walkup.urdf"),
    ("urdf-package-walks-up-init", "robot init {W}/u/walkup.urdf"),
]
CASES_IN_SUBPROCESS = [      # used to read until MemoryError, hang, allocate 5 GB or hang in datagen
    ("include-dev-zero", GEN % "zero.xml"),
    ("include-fifo", GEN % "fifo.xml"),
    ("texture-30000", GEN % "texture.xml"),
    ("timestep-1e-12", GEN % "tiny_step.xml"),
    ("timestep-1e-8", GEN % "small_step.xml"),
]
WORDS = {   # what the one line must say
    "include-absolute-path": ["include '/etc/passwd' named by", "passwd.xml", "must be inside"],
    "include-dotdot-out-of-the-folder": ["include '../inc.xml' named by", "must be inside"],
    "include-missing": ["include 'nothere.xml' of", "missing_inc.xml", "an existing file"],
    "model-not-utf8": ["latin1.xml must be UTF-8 text"],
    "model-doctype-entity": ["entity.xml must be XML without a DOCTYPE"],
    "offscreen-30000": ["offwidth", "at most 4096 px"],
    "mesh-degenerate": ["degenerate.xml must be one MuJoCo compiles", "collinear"],
    "urdf-cyclic": ["cyclic.urdf must be a robot MuJoCo parses"],
    "urdf-absolute-mesh": ["absolute.urdf", "must be inside"],
    "urdf-dotdot-mesh": ["dotdot.urdf", "must be inside"],
    "urdf-package-walks-up": ["walkup.urdf", "nopkg"],
    "include-dev-zero": ["include '/dev/zero' named by", "must be inside"],
    "include-fifo": ["include 'pipe.xml' of", "must be a regular file", "a FIFO"],
    "texture-30000": ["texture 'big'", "at most 4096 px a side"],
    "timestep-1e-12": ["<option timestep>", "must be in [0.0001, 0.1] s"],
    "timestep-1e-8": ["<option timestep>", "must be in [0.0001, 0.1] s"],
}


def _arm(head: str = "", asset: str = "", geom: str = "") -> str:
    """ARM (tests/reliability/test_robot.py) with `head` after <mujoco>, an <asset> block and a geom on the link."""
    text = ARM.replace('<compiler angle="radian"/>', f'<compiler angle="radian"/>{head}')
    if asset:
        text = text.replace("<worldbody>", f"<asset>{asset}</asset><worldbody>", 1)
    return text.replace('<site name="tip"', f'{geom}<site name="tip"')


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("robot_files"))


def make_world(w):
    """Model files each wrong in one way, the files they point at, and a FIFO."""
    (w / "passwd.xml").write_text(_arm('<include file="/etc/passwd"/>'))
    (w / "sub").mkdir()
    (w / "inc.xml").write_text("<mujoco/>")
    (w / "sub" / "dotdot.xml").write_text(_arm('<include file="../inc.xml"/>'))
    (w / "missing_inc.xml").write_text(_arm('<include file="nothere.xml"/>'))
    (w / "latin1.xml").write_bytes(_arm("<!-- caf\xe9 -->").encode("latin-1"))
    (w / "entity.xml").write_text('<!DOCTYPE mujoco [<!ENTITY big "x">]>' + _arm())
    (w / "offwidth.xml").write_text(_arm('<visual><global offwidth="30000" offheight="30000"/></visual>'))
    (w / "degenerate.xml").write_text(_arm(asset='<mesh name="flat" vertex="0 0 0 1 0 0 2 0 0 3 0 0"/>',
                                           geom='<geom type="mesh" mesh="flat"/>'))
    (w / "zero.xml").write_text(_arm('<include file="/dev/zero"/>'))
    os.mkfifo(w / "pipe.xml")
    (w / "fifo.xml").write_text(_arm('<include file="pipe.xml"/>'))
    (w / "texture.xml").write_text(_arm(asset='<texture name="big" type="2d" builtin="checker" width="30000" '
                                              'height="30000"/>'))
    (w / "tiny_step.xml").write_text(_arm('<option timestep="1e-12"/>'))
    (w / "small_step.xml").write_text(_arm('<option timestep="1e-8"/>'))
    (w / "m").mkdir()
    (w / "m" / "tip.stl").write_bytes(STL)
    (w / "u").mkdir()
    (w / "u" / "cyclic.urdf").write_text(CYCLIC)
    for name, file in (("absolute", str(w / "m" / "tip.stl")), ("dotdot", "../m/tip.stl"),
                       ("walkup", "package://nopkg/m/tip.stl")):
        (w / "u" / f"{name}.urdf").write_text(URDF.format(visuals=VISUAL.format(file=file)))
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_robot_file_is_a_clear_error(case_id, command, in_world, capsys):
    err = run_and_check(case_id, command, in_world, capsys)
    for words in WORDS.get(case_id, []):
        assert words in err, err
    assert "Check the path given on the command line" not in err, err     # an include is not on the command line
    assert len([line for line in err.splitlines() if "error:" in line]) == 1 and "\\n" not in err, err   # one line


def _limited():
    resource.setrlimit(resource.RLIMIT_AS, (6 * 2**30, 6 * 2**30))      # a regression fails, the machine survives


@pytest.mark.parametrize("case_id, command", CASES_IN_SUBPROCESS, ids=[c[0] for c in CASES_IN_SUBPROCESS])
def test_blocking_or_huge_robot_file_is_refused_quickly(case_id, command, in_world):
    before = snapshot(in_world)
    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG")}
    try:
        done = subprocess.run([sys.executable, "-m", "bodyschema.cli", *command.format(W=in_world).split()],
                              cwd=in_world, env={**env, "MUJOCO_GL": "egl"}, capture_output=True, text=True,
                              timeout=60, preexec_fn=_limited)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{case_id}: still running after 60 s")
    check_clear_failure(case_id, done.returncode, done.stderr, before, snapshot(in_world), in_world)
    for words in WORDS[case_id]:
        assert words in done.stderr, done.stderr


@pytest.fixture
def urdf_of_one_mesh(tmp_path):
    """A URDF showing one STL in 60 visuals (the 50 MB mesh of item 7, in small)."""
    (tmp_path / "tip.stl").write_bytes(STL)
    path = tmp_path / "many.urdf"
    path.write_text(URDF.format(visuals="".join(VISUAL.format(file="tip.stl") for _ in range(60))))
    return path


def test_a_mesh_shown_by_many_links_is_read_and_compiled_once(urdf_of_one_mesh, monkeypatch):
    record, reads = infer_record(urdf_of_one_mesh), []
    real = model_files.read_regular
    monkeypatch.setattr(model_files, "read_regular", lambda *a: reads.append(a[0]) or real(*a))
    spec, source = read_source(record)
    assert len(spec.meshes) == 1 and list(source.meshes) == ["tip.stl"]
    assert reads.count(urdf_of_one_mesh.parent / "tip.stl") == 1


def test_a_mesh_over_the_size_cap_is_refused_before_mujoco_reads_it(urdf_of_one_mesh, monkeypatch):
    monkeypatch.setattr(model_files, "MAX_FILE_BYTES", len(STL) - 1)
    with pytest.raises(ValueError, match=r"visual mesh 'tip.stl' of .*many.urdf must be a file of at most"):
        infer_record(urdf_of_one_mesh)


def test_the_files_of_one_robot_have_a_total_cap(tmp_path, monkeypatch):
    for i in range(3):
        (tmp_path / f"m{i}.stl").write_bytes(STL)
    (tmp_path / "three.urdf").write_text(URDF.format(visuals="".join(VISUAL.format(file=f"m{i}.stl")
                                                                     for i in range(3))))
    monkeypatch.setattr(model_files, "MAX_TOTAL_BYTES", 2 * len(STL) + 1000)   # the URDF and two meshes fit
    with pytest.raises(ValueError, match="must be at most .* together"):
        infer_record(tmp_path / "three.urdf")


def test_too_many_mesh_elements_are_refused_before_compiling(tmp_path, monkeypatch):
    monkeypatch.setattr(model_files, "MAX_ASSETS", 3)
    meshes = "".join(f'<mesh name="m{i}" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/>' for i in range(4))
    (tmp_path / "many.xml").write_text(_arm(asset=meshes))
    with pytest.raises(ValueError, match="must be at most 3 meshes"):
        infer_record(tmp_path / "many.xml")
