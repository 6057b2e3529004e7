"""`bodyschema import` keeps a LeRobot dataset's `action` as the store's `target` where it commands the state's
joints (its names are the state's, in any order), and says in one line every feature it does not import and why
(also kept in the store's `source.not_imported`). `--joints` without `--ranges` takes the data's box as the limits."""

from __future__ import annotations

import json
import logging
import shutil

import numpy as np
import pytest
import zarr

from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.import_sources import planar2_frames, write_folder

pa = pytest.importorskip("pyarrow")
pq = pytest.importorskip("pyarrow.parquet")
LOGGER = "bodyschema.datagen.exchange.importers.run"


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    """A babbling store (targets recorded) and its LeRobot export without meta/bodyschema.json (a foreign dataset)."""
    from tests.datagen.export_stores import foreign_lerobot

    store, foreign = foreign_lerobot(tmp_path_factory.mktemp("action"), "foreign")
    return zarr.open_group(str(store), mode="r"), foreign


KEEP = "keep"          # edited(): leave the action's names as they are


def edited(source, folder, names=KEEP, action=None):
    """A copy of the LeRobot dataset `source` with the action's names and/or values (a function of the column)
    replaced."""
    out = shutil.copytree(source, folder)
    info = json.loads((out / "meta" / "info.json").read_text())
    if names != KEEP:
        info["features"]["action"]["names"] = names
        (out / "meta" / "info.json").write_text(json.dumps(info))
    for path in (out / "data").rglob("*.parquet"):
        table = pq.read_table(path)
        values = np.stack(table.column("action").to_numpy(zero_copy_only=False))              # (n, K)
        values = action(values) if action is not None else values
        column = pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1).astype(np.float32)), values.shape[1])
        table = table.set_column(table.schema.get_field_index("action"), "action", column)
        pq.write_table(table.replace_schema_metadata(pq.read_schema(path).metadata), path)
    return out


def dropped_lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == LOGGER and "not imported" in r.getMessage()]


def test_a_foreign_action_naming_the_state_joints_is_kept_as_the_target(exports, tmp_path, caplog):
    """Named in the other order (the values permuted with the names): each joint's command still lands on it."""
    store, foreign = exports
    source = edited(foreign, tmp_path / "reversed", names=["elbow", "shoulder"], action=lambda v: v[:, ::-1])
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        back = import_recording(ImportConfig(source=source, out=tmp_path / "t.zarr", angles="rad", robot="planar2"))
    assert validate_store(back) == []
    root = zarr.open_group(str(back), mode="r")
    np.testing.assert_array_equal(root["target"][:], store["target"][:])                # float32 both ways
    assert root.attrs["features"]["target"]["unit"] == "rad"
    lines = dropped_lines(caplog)
    assert len(lines) == 1 and "action" not in lines[0] and "observation.velocity" in lines[0], lines
    assert "action" not in root.attrs["source"]["not_imported"]


def test_a_foreign_action_in_degrees_is_converted_like_the_angles(exports, tmp_path):
    store, foreign = exports
    source = shutil.copytree(foreign, tmp_path / "deg")
    for path in (source / "data").rglob("*.parquet"):
        table = pq.read_table(path)
        for key in ("observation.state", "action"):
            values = np.rad2deg(np.stack(table.column(key).to_numpy(zero_copy_only=False)))
            column = pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1)), values.shape[1])
            table = table.set_column(table.schema.get_field_index(key), key, column)
        pq.write_table(table, path)
    back = import_recording(ImportConfig(source=source, out=tmp_path / "d.zarr", angles="deg", robot="planar2"))
    np.testing.assert_allclose(zarr.open_group(str(back), mode="r")["target"][:], store["target"][:], atol=1e-6)


@pytest.mark.parametrize("names, reason", [
    (["x", "y"], "it commands ['x', 'y'], not the joints of observation.state"),
    (None, "the joints it commands are not named"),
])
def test_an_action_of_other_joints_is_dropped_and_said_in_one_line(exports, tmp_path, caplog, names, reason):
    store, foreign = exports
    source = edited(foreign, tmp_path / "other", names=names)
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        back = import_recording(ImportConfig(source=source, out=tmp_path / "o.zarr", angles="rad", robot="planar2"))
    root = zarr.open_group(str(back), mode="r")
    assert "target" not in root.array_keys()
    lines = dropped_lines(caplog)
    assert len(lines) == 1 and reason in lines[0] and "action (" in lines[0], lines
    assert reason in root.attrs["source"]["not_imported"]["action"]


def test_commands_outside_the_joint_limits_are_dropped_with_the_reason(exports, tmp_path, caplog):
    store, foreign = exports
    source = edited(foreign, tmp_path / "far", action=lambda v: v * 10)          # rad read as if deg/10: off-limits
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        back = import_recording(ImportConfig(source=source, out=tmp_path / "f.zarr", angles="rad", robot="planar2"))
    assert validate_store(back) == [] and "target" not in zarr.open_group(str(back), mode="r").array_keys()
    assert "commands outside the joint limits" in dropped_lines(caplog)[0]


def test_our_export_of_poses_says_its_action_was_made_from_the_state(tmp_path, caplog):
    from tests.datagen.export_stores import uniform_store

    out = export_dataset(uniform_store(tmp_path), tmp_path / "uniform", "lerobot")
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        import_recording(ImportConfig(source=out, out=tmp_path / "u.zarr"))
    lines = dropped_lines(caplog)
    assert len(lines) == 1 and "action (made by the export from the state" in lines[0], lines


def test_our_export_with_targets_imports_with_nothing_dropped(exports, tmp_path, caplog):
    store, _ = exports
    out = export_dataset(_store_path(store), tmp_path / "own", "lerobot")
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        back = import_recording(ImportConfig(source=out, out=tmp_path / "own.zarr"))
    assert dropped_lines(caplog) == []
    np.testing.assert_array_equal(zarr.open_group(str(back), mode="r")["target"][:], store["target"][:])


def _store_path(group):
    from pathlib import Path

    return Path(str(group.store.root))


def test_joints_without_ranges_take_the_datas_box(tmp_path):
    q, images = planar2_frames(12)
    folder = write_folder(tmp_path / "rec", q, images, order=[1, 0])                  # elbow first, in degrees
    back = import_recording(ImportConfig(source=folder, out=tmp_path / "j.zarr", angles="deg",
                                         joints=("shoulder", "elbow")))
    assert validate_store(back) == []
    attrs = zarr.open_group(str(back), mode="r").attrs
    box = np.stack([q.min(axis=0), q.max(axis=0)], axis=1)                            # (2, 2) rad, body order
    np.testing.assert_allclose(attrs["joint_limits"], box, atol=1e-12)               # CSV's 17 digits, deg → rad
    np.testing.assert_allclose(attrs["sampling_ranges"], box, atol=1e-6)              # of q as stored (float32)


def test_joints_without_ranges_box_the_commands_too(exports, tmp_path):
    """A commanded target past every angle reached still lies inside the limits (the box of all joint values)."""
    store, foreign = exports
    back = import_recording(ImportConfig(source=foreign, out=tmp_path / "b.zarr", angles="rad",
                                         joints=("shoulder", "elbow")))
    assert validate_store(back) == []
    root = zarr.open_group(str(back), mode="r")
    values = np.concatenate([store["q"][:], store["target"][:]]).astype(np.float64)
    np.testing.assert_allclose(root.attrs["joint_limits"], np.stack([values.min(0), values.max(0)], axis=1),
                               atol=1e-12)
    q = store["q"][:].astype(np.float64)
    np.testing.assert_allclose(root.attrs["sampling_ranges"], np.stack([q.min(0), q.max(0)], axis=1), atol=1e-12)


def test_an_hdf5_demos_actions_and_unread_keys_are_said(tmp_path, caplog):
    import h5py

    from tests.datagen.import_sources import write_demo_hdf5

    q, images = planar2_frames(6)
    path = write_demo_hdf5(tmp_path / "demo.hdf5", q, images, episodes=2)
    with h5py.File(path, "r+") as f:
        for group in f["data"].values():
            group["actions"] = np.zeros((len(group["obs/joint_pos"]), 7))           # robomimic: ee deltas + gripper
            group["obs/joint_vel"] = np.zeros_like(group["obs/joint_pos"])
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        import_recording(ImportConfig(source=path, out=tmp_path / "h.zarr", angles="rad", robot="planar2",
                                      joint_key=("joint_pos",)))
    lines = dropped_lines(caplog)
    assert len(lines) == 1 and "obs/joint_vel (not asked for" in lines[0] and "actions (no store array" in lines[0]
