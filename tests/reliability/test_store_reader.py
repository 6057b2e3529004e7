"""datagen owns the read side of a store (issue 22, item 3): training, export, import and evaluation read through
`datagen.store.reader`, with the digests and the body they had before, and stores (or exports) edited where the old
body readers differed are refused by every reader alike. Bad command lines are one line each in CASES, run through the
fuzz harness of tests/test_cli_fuzz.py (the extended fuzz test beside it)."""

from __future__ import annotations

import ast
import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import zarr

from bodyschema.base.outputs import marker_path
from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.store import reader as store_reader
from bodyschema.datagen.store.schema import DONE, open_store
from bodyschema.training.data import load_dataset
from tests.test_cli_fuzz import build_world, run_and_check

h5py, _ = pytest.importorskip("h5py"), pytest.importorskip("pyarrow")   # the export formats
REPO = Path(__file__).resolve().parents[2]
TRAIN = "train gpr --modality ee_xyz --data"
CASES = [
    ("train-no-sampling-ranges", TRAIN + " {W}/no_ranges.zarr"),
    ("train-sampling-ranges-null", TRAIN + " {W}/null_ranges.zarr"),
    ("train-one-joint-name-short", TRAIN + " {W}/short_names.zarr"),
    ("export-no-sampling-ranges", "export dataset --to hdf5 {W}/no_ranges.zarr {W}/o.h5"),
    ("export-sampling-ranges-null", "export dataset --to lerobot {W}/null_ranges.zarr {W}/o"),
    ("export-one-joint-name-short", "export dataset --to hdf5 {W}/short_names.zarr {W}/o.h5"),
    ("export-not-a-store", "export dataset --to hdf5 {W}/notastore {W}/o.h5"),
    ("export-bad-json", "export dataset --to hdf5 {W}/badjson.zarr {W}/o.h5"),
    ("import-export-without-sampling-ranges", "import {W}/no_ranges.h5 --out {W}/new.zarr"),
    ("import-export-sampling-ranges-null", "import {W}/null_ranges.h5 --out {W}/new.zarr"),
    ("import-export-one-joint-name-short", "import {W}/short_names.h5 --out {W}/new.zarr"),
    ("levels-targets-no-sampling-ranges", "evaluate levels --targets {W}/no_ranges.zarr --trials 2 --runs 1 "
                                          "--no-mlflow --out {W}/res"),
]
# Where the old readers of the body differed: training fell back to q's observed range, export to the joint limits.
EDITS = {"no_ranges": lambda attrs: attrs.__delitem__("sampling_ranges"),
         "null_ranges": lambda attrs: attrs.__setitem__("sampling_ranges", None),
         "short_names": lambda attrs: attrs.__setitem__("joint_names", attrs["joint_names"][:1])}


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    return make_world(tmp_path_factory.mktemp("store_reader"))


def make_world(w: Path) -> Path:
    """The fuzz world plus, for each of EDITS, its valid store with the body attrs so edited (`<edit>.zarr`) and
    an HDF5 export of it whose copy of the store attrs is (`<edit>.h5`)."""
    build_world(w)
    export_dataset(w / "good.zarr", w / "good.h5", "hdf5")
    for name, edit in EDITS.items():
        shutil.copytree(w / "good.zarr", w / f"{name}.zarr")
        group = zarr.open_group(str(w / f"{name}.zarr"), mode="r+")
        attrs = dict(group.attrs)
        edit(attrs)
        group.attrs.clear()
        group.attrs.update(attrs)
        shutil.copy(w / "good.h5", w / f"{name}.h5")
        with h5py.File(w / f"{name}.h5", "r+") as f:
            f.attrs["store_attrs"] = json.dumps(attrs)
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_a_bad_store_is_a_clear_error_for_every_reader(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)


# ---- the digests recorded before the reader moved ----------------------------------------------------------
def old_dataset_digest(path: Path) -> str:
    """training.data.store_digest as it was (a store with checksums): names, dtypes, shapes, then shard checksums."""
    root = zarr.open_group(str(path), mode="r")
    digest = hashlib.sha256(b"bodyschema-store;")
    names = sorted(name for name in root.array_keys() if name != DONE)
    for name in names:
        digest.update(f"{name}|{root[name].dtype}|{root[name].shape};".encode())
    digest.update(np.asarray(root[DONE][:]).astype("<u8").tobytes())
    return digest.hexdigest()


def old_source_digest(path: Path) -> str:
    """datagen.exchange.export.source_digest as it was: the root attrs as sorted JSON, then the shard checksums."""
    root = zarr.open_group(str(path), mode="r")
    h = hashlib.sha256(json.dumps(dict(root.attrs), sort_keys=True, default=str).encode())
    h.update(np.asarray(root[DONE][:]).astype(np.uint64).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("store, modalities", [("good.zarr", ("ee_xyz", "jacobian", "ee_xyz,ee_pixel")),
                                               ("img.zarr", ("image", "ee_xyz,image"))])
def test_training_records_the_dataset_digest_it_recorded_before(world, store, modalities):
    want = old_dataset_digest(world / store)
    for modality in modalities:
        assert load_dataset(world / store, modality).sha256 == want, modality
    assert store_reader.store_digest(open_store(world / store)) == want
    assert want != old_dataset_digest(world / ("img.zarr" if store == "good.zarr" else "good.zarr"))


@pytest.mark.parametrize("to", ["hdf5", "lerobot"])
def test_an_export_records_the_source_digest_it_recorded_before(world, tmp_path, to):
    out = export_dataset(world / "img.zarr", tmp_path / "out", to)
    marker = json.loads(marker_path(out).read_text())
    assert marker["source"]["digest"] == old_source_digest(world / "img.zarr")


def test_a_store_without_checksums_has_no_digest(world, tmp_path):
    copy = shutil.copytree(world / "good.zarr", tmp_path / "flags.zarr")
    group = zarr.open_group(str(copy), mode="r+")
    del group[DONE]
    group.create_array(DONE, shape=(2,), chunks=(1,), dtype="uint8", fill_value=1)   # schema 1: bare flags
    for digest in (store_reader.store_digest, store_reader.source_digest):
        with pytest.raises(ValueError, match="must be one with per-shard checksums"):
            digest(open_store(copy))


# ---- one body reader -------------------------------------------------------------------------------------------
def test_training_and_export_read_the_same_body_the_sampled_box(world, tmp_path):
    attrs = dict(open_store(world / "good.zarr").attrs)
    body = load_dataset(world / "good.zarr", "ee_xyz").body
    assert (body.robot, list(body.joint_names)) == (attrs["robot"], attrs["joint_names"])
    np.testing.assert_array_equal(np.array([body.q_low, body.q_high]).T, attrs["sampling_ranges"])
    with h5py.File(export_dataset(world / "good.zarr", tmp_path / "d.h5", "hdf5"), "r") as f:
        exported = {key: f["body"].attrs[key] for key in ("q_low", "q_high")}
    np.testing.assert_array_equal(exported["q_low"], body.q_low)
    np.testing.assert_array_equal(exported["q_high"], body.q_high)


@pytest.mark.parametrize("edited", sorted(EDITS))
def test_no_reader_falls_back_when_the_body_attrs_are_edited(world, edited):
    """Neither old fallback (q's range, the joint limits) is taken: the store is refused, and the reader itself,
    given the edited store directly, raises the house error naming the attr."""
    path = world / f"{edited}.zarr"
    with pytest.raises(ValueError, match="cannot be used for training"):
        load_dataset(path, "ee_xyz")
    with pytest.raises(ValueError, match="STORE must be a complete, valid store"):
        export_dataset(path, world / "never.h5", "hdf5")
    assert not (world / "never.h5").exists()
    attr = "joint_names" if edited == "short_names" else "sampling_ranges"
    with pytest.raises(ValueError, match=rf"data attrs\['{attr}'\] must be"):
        store_reader.store_body(open_store(path))


# ---- one owner: one open, training without zarr, no back edge --------------------------------------------------
def test_check_store_opens_the_group_once(world, monkeypatch):
    opened = []
    real = zarr.open_group
    monkeypatch.setattr(zarr, "open_group", lambda *a, **k: opened.append(a) or real(*a, **k))
    store = store_reader.check_store(world / "good.zarr", ("q", "ee_xyz"))
    assert store.problems == () and len(opened) == 1


def test_a_missing_array_is_one_more_problem_with_its_hint(world):
    store = store_reader.check_store(world / "good.zarr", ("q", "image"), hints={"image": "Pick another."})
    (problem,) = store.problems
    assert problem.startswith("data array 'image' must be present") and problem.endswith("Pick another.")
    assert all(name in problem for name in store_reader.data_arrays(store.root)) and DONE not in problem


def imported_modules(folder: Path) -> set[tuple[str, str]]:
    """(file, module) of every import statement in the package folder."""
    found = set()
    for path in sorted(folder.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {(path.name, alias.name) for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                found.add((path.name, node.module))
    return found


def test_training_reads_stores_only_through_datagen():
    zarr_users = sorted(f for f, module in imported_modules(REPO / "training") if module.split(".")[0] == "zarr")
    assert zarr_users == [], f"training modules importing zarr: {zarr_users}"


def test_datagen_never_imports_training():
    back = sorted(f for f, module in imported_modules(REPO / "datagen") if module.startswith("bodyschema.training"))
    assert back == [], f"datagen modules importing training (a back edge): {back}"
