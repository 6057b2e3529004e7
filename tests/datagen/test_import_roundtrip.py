"""Export → import reproduces every array: a store written as HDF5 or as a LeRobot v3.0 dataset and imported back
(no body flags: the export records it) holds the same arrays, dtypes and joint box, validates, and records its
source and the source's digest. The panda store brings a 1-wide array (touch, (N, 1)), which LeRobot's layout writes
as a scalar column. A babbling store's servo targets come back from LeRobot's `action`; a store made before datagen
recorded them comes back without (its `action` was the next state, not an array of the store)."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.recording import source_sha256
from bodyschema.datagen.exchange.importers.run import import_recording
from bodyschema.datagen.generate import generate
from bodyschema.datagen.store.schema import DONE
from bodyschema.datagen.store.validate import validate_store
from tests.datagen.export_stores import babble_store, older_store, uniform_store

pytest.importorskip("h5py")
pytest.importorskip("pyarrow")


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stores")
    panda = DatagenConfig(robot="panda", n=30, sampler="babble", episode_s=1.0, record_hz=10.0, image_size=(24, 32),
                          rgb=True, out=folder / "panda.zarr")                      # touch (N, 1), 3 episodes
    babble = babble_store(folder)
    return {"babble": babble, "uniform": uniform_store(folder), "panda": generate(panda),
            "old": older_store(babble, folder / "old.zarr")}


@pytest.mark.parametrize("to", ["hdf5", "lerobot"])
@pytest.mark.parametrize("which", ["babble", "uniform", "panda", "old"])
def test_export_then_import_reproduces_every_array(stores, which, to, tmp_path):
    store = stores[which]
    exported = export_dataset(store, tmp_path / ("d.h5" if to == "hdf5" else "d_lerobot"), to)
    back = import_recording(ImportConfig(source=exported, out=tmp_path / "back.zarr"))
    assert validate_store(back) == []
    old, new = zarr.open_group(str(store), mode="r"), zarr.open_group(str(back), mode="r")
    names = sorted(k for k in old.array_keys() if k != DONE)
    assert which != "panda" or old["touch"].shape[1:] == (1,)                 # the 1-wide case is really covered
    assert ("target" in old.array_keys()) == (which in ("babble", "panda"))   # the servo targets are covered too
    assert sorted(k for k in new.array_keys() if k != DONE) == names
    for name in names:
        want, got = np.asarray(old[name][:]), np.asarray(new[name][:])
        assert got.dtype == want.dtype and got.shape == want.shape, name
        np.testing.assert_array_equal(got, want, err_msg=name)
    for key in ("robot", "joint_names", "joint_limits", "sampling_ranges", "intrinsics", "extrinsics", "reach_m"):
        assert new.attrs[key] == old.attrs[key], key
    source = new.attrs["source"]
    files = [exported] if exported.is_file() else [p for p in exported.rglob("*") if p.is_file()]
    assert source["format"] == to and source["sha256"] == source_sha256(files, exported if exported.is_dir()
                                                                         else exported.parent)


def test_the_source_digest_changes_with_one_byte(stores, tmp_path):
    exported = export_dataset(stores["uniform"], tmp_path / "d.h5", "hdf5")
    first = source_sha256([exported], tmp_path)
    data = bytearray(exported.read_bytes())
    data[-1] ^= 1
    exported.write_bytes(bytes(data))
    assert source_sha256([exported], tmp_path) != first


def test_an_ee_rot_that_is_not_a_rotation_is_refused_and_nothing_is_written(stores, tmp_path):
    import h5py

    exported = export_dataset(stores["uniform"], tmp_path / "d.h5", "hdf5")
    with h5py.File(exported, "r+") as f:
        rot = f["ee_rot"][:]
        rot[3] *= 1.01                                          # a matrix scaled by 1 %: |RᵀR − I| ≈ 0.02
        f["ee_rot"][:] = rot
    with pytest.raises(ValueError, match=r"ee_rot in .* must be rotation matrices read row by row .* at row 4 "
                                         r"\(1 rows\)"):
        import_recording(ImportConfig(source=exported, out=tmp_path / "back.zarr"))
    assert not (tmp_path / "back.zarr").exists()
