"""Bad input to `bodyschema import` and to `evaluate levels --targets` (the extended fuzz test beside
tests/test_cli_fuzz.py, with its harness): every
case exits 2 with the house message, no traceback, and the scratch folder unchanged — no store and no temporary
sibling left behind, even when the failure comes after the store was written (an edited export that fails
validation). Adding a case is one line in CASES."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from tests.datagen.import_sources import planar2_frames, write_demo_hdf5, write_folder
from tests.test_cli_fuzz import run_and_check, run_in_process

OUT = "--out {W}/new.zarr"
LEVELS = "--trials 2 --runs 1 --no-mlflow --out {W}/res"
CASES = [
    ("no-angles-unit", "import {W}/rec --robot planar2 " + OUT),
    ("rows-not-images", "import {W}/short --angles deg --robot planar2 " + OUT),
    ("nan-angle", "import {W}/nan --angles deg --robot planar2 " + OUT),
    ("angle-out-of-range", "import {W}/far --angles deg --robot planar2 " + OUT),
    ("angles-in-rad-read-as-deg-limits", "import {W}/rec --angles rad --robot planar2 " + OUT),
    ("mixed-image-sizes", "import {W}/mixed --angles deg --robot planar2 " + OUT),
    ("mixed-channels", "import {W}/colours --angles deg --robot planar2 " + OUT),
    ("unknown-joint-column", "import {W}/wrist --angles deg --robot planar2 " + OUT),
    ("16-bit-image", "import {W}/deep --angles deg --robot planar2 " + OUT),
    ("bad-cell", "import {W}/word --angles deg --robot planar2 " + OUT),
    ("no-body", "import {W}/rec --angles deg " + OUT),
    ("two-bodies", "import {W}/rec --angles deg --robot planar2 --joints shoulder elbow " + OUT),
    ("ranges-reversed", "import {W}/rec --angles deg --joints shoulder elbow --ranges 1 0 0 1 " + OUT),
    ("ranges-count", "import {W}/rec --angles deg --robot planar2 --ranges -90 90 " + OUT),
    ("ranges-outside-limits", "import {W}/rec --angles deg --robot planar2 --ranges -900 90 -90 90 " + OUT),
    ("fk-without-robot", "import {W}/rec --angles deg --joints shoulder elbow --ranges -180 180 -180 180 --fk "
                         + OUT),
    ("robot-unknown", "import {W}/rec --angles deg --robot mars " + OUT),
    ("angles-unit-unknown", "import {W}/rec --angles grad --robot planar2 " + OUT),
    ("resize-0", "import {W}/rec --angles deg --robot planar2 --resize 0 0 " + OUT),
    ("crop-outside", "import {W}/rec --angles deg --robot planar2 --crop 10 10 100 100 " + OUT),
    ("source-missing", "import {W}/missing --angles deg --robot planar2 " + OUT),
    ("source-not-a-dataset", "import {W}/note.txt --angles deg --robot planar2 " + OUT),
    ("csv-missing", "import {W}/rec --csv {W}/none.csv --angles deg --robot planar2 " + OUT),
    ("out-exists", "import {W}/rec --angles deg --robot planar2 --out {W}/demo.h5"),
    ("out-is-the-source", "import {W}/rec --angles deg --robot planar2 --overwrite --out {W}/rec"),
    ("out-inside-the-source", "import {W}/rec --angles deg --robot planar2 --out {W}/rec/new.zarr"),
    ("overwrite-not-an-import", "import {W}/rec --angles deg --robot planar2 --overwrite --out {W}/demo.h5"),
    ("demo-no-joint-key", "import {W}/demo.h5 --angles rad --robot planar2 " + OUT),
    ("demo-unknown-key", "import {W}/demo.h5 --angles rad --robot planar2 --joint-key robot0_joint_pos " + OUT),
    ("demo-unknown-image-key", "import {W}/demo.h5 --angles rad --robot planar2 --joint-key joint_pos "
                               "--image-key wrist_image " + OUT),
    ("hdf5-not-hdf5", "import {W}/fake.h5 --angles rad --robot planar2 " + OUT),
    ("own-export-read-as-deg", "import {W}/own.h5 --angles deg " + OUT),
    ("own-export-edited-fails-validation", "import {W}/edited.h5 " + OUT),
    ("own-export-jacobian-beyond-reach", "import {W}/far.h5 " + OUT),
    ("lerobot-v2", "import {W}/lerobot_v2 --angles rad --robot planar2 " + OUT),
    ("levels-targets-missing", "evaluate levels --targets {W}/missing.zarr " + LEVELS),
    ("levels-targets-not-a-store", "evaluate levels --targets {W}/rec " + LEVELS),
    ("levels-targets-other-robot", "evaluate levels --model analytic:nao_arm:ee_xyz --targets {W}/fk.zarr " + LEVELS),
    ("levels-targets-without-ee", "evaluate levels --targets {W}/q_only.zarr " + LEVELS),
    ("levels-targets-too-few", "evaluate levels --targets {W}/fk.zarr --trials 4 --runs 2 --no-mlflow --out {W}/res"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("import_fuzz"))


def make_world(w):
    import cv2

    q, images = planar2_frames(6)
    write_folder(w / "rec", q, images)
    write_folder(w / "short", q, images).joinpath("img5.png").unlink()
    write_folder(w / "nan", q, images)
    _set_cell(w / "nan" / "angles.csv", 4, 0, "nan")
    write_folder(w / "far", q, images)
    _set_cell(w / "far" / "angles.csv", 2, 0, "400.0")
    write_folder(w / "mixed", q, images)
    cv2.imwrite(str(w / "mixed" / "img2.png"), np.zeros((30, 24), np.uint8))
    write_folder(w / "colours", q, images)
    cv2.imwrite(str(w / "colours" / "img2.png"), np.zeros((24, 24, 3), np.uint8))
    write_folder(w / "wrist", q, images)
    _set_cell(w / "wrist" / "angles.csv", 0, 1, "wrist")
    write_folder(w / "deep", q, images)
    cv2.imwrite(str(w / "deep" / "img1.png"), np.zeros((24, 24), np.uint16))
    write_folder(w / "word", q, images)
    _set_cell(w / "word" / "angles.csv", 3, 1, "ninety")
    (w / "note.txt").write_text("not a recording")
    (w / "fake.h5").write_text("not HDF5")
    write_demo_hdf5(w / "demo.h5", q, images, episodes=2)
    _stores(w)
    _own_exports(w)
    (w / "lerobot_v2" / "meta").mkdir(parents=True)
    (w / "lerobot_v2" / "meta" / "info.json").write_text(json.dumps({"codebase_version": "v2.1", "features": {}}))
    return w


def _stores(w) -> None:
    """Level targets: fk.zarr (the good recording with its forward kinematics), q_only.zarr (angles only)."""
    from bodyschema.datagen.exchange.importers.config import ImportConfig
    from bodyschema.datagen.exchange.importers.run import import_recording

    import_recording(ImportConfig(source=w / "rec", out=w / "fk.zarr", angles="deg", robot="planar2", fk=True))
    import_recording(ImportConfig(source=w / "rec", out=w / "q_only.zarr", angles="deg", robot="planar2",
                                  images=False))


def _set_cell(path, row: int, col: int, value: str) -> None:
    rows = [line.split(",") for line in path.read_text().splitlines()]
    rows[row][col] = value
    path.write_text("\n".join(",".join(r) for r in rows) + "\n")


def _own_exports(w) -> None:
    """own.h5: a planar2 store exported; edited.h5: the same with ee_pixel moved 5 px off the camera's projection;
    far.h5: with a jacobian 100 times the arm's reach."""
    import shutil

    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.exchange.export import export_dataset
    from bodyschema.datagen.generate import generate

    store = generate(DatagenConfig(robot="planar2", n=8, images=False, out=w / "tmp_store.zarr"), progress=False)
    export_dataset(store, w / "own.h5", "hdf5")
    shutil.rmtree(store)
    shutil.copy(w / "own.h5", w / "edited.h5")
    with h5py.File(w / "edited.h5", "r+") as f:
        f["ee_pixel"][...] = f["ee_pixel"][()] + 5.0
    shutil.copy(w / "own.h5", w / "far.h5")
    with h5py.File(w / "far.h5", "r+") as f:
        f["jacobian"][...] = f["jacobian"][()] * 100.0


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_import_is_a_clear_error_and_writes_nothing(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)


def test_the_good_recording_of_the_world_imports(in_world, capsys):
    """The cases fail for their one defect: the same folder without it imports and validates."""
    code, err = run_in_process(f"import {in_world}/rec --angles deg --robot planar2 --out {in_world}/ok.zarr"
                               .split(), capsys)
    assert code == 0, err
    import shutil
    shutil.rmtree(in_world / "ok.zarr")


def test_a_store_failing_validation_is_blamed_on_the_recording_not_on_datagen(in_world, capsys):
    """The validate lines of an import carry no datagen hint ("rerun datagen", "the generator wrote impossible
    values"): the recording is at fault, and the line says to fix it."""
    err = run_and_check("own-export-jacobian-beyond-reach", dict(CASES)["own-export-jacobian-beyond-reach"],
                        in_world, capsys)
    assert "Fix the recording" in err and "jacobian" in err, err
    assert "datagen" not in err and "generator" not in err, err
