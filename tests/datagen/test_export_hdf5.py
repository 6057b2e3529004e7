"""`export_dataset(..., "hdf5")`: every array read back with h5py equals the store's, with its units, names, the body
spec and the store's attrs; invalid stores and existing outputs are refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
import zarr

from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.store.schema import DONE
from tests.datagen.export_stores import babble_store, uniform_store

h5py = pytest.importorskip("h5py")


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stores")
    return {"babble": babble_store(folder), "uniform": uniform_store(folder)}


@pytest.mark.parametrize("which", ["babble", "uniform"])
def test_every_array_round_trips_with_its_metadata(stores, which, tmp_path):
    store = stores[which]
    out = export_dataset(store, tmp_path / "d.h5", "hdf5")
    root = zarr.open_group(str(store), mode="r")
    names = sorted(k for k in root.array_keys() if k != DONE)
    assert ("target" in names) == (which == "babble")                 # the servo targets are carried too
    with h5py.File(out, "r") as f:
        assert sorted(k for k in f.keys() if k != "body") == names
        for name in names:
            want = np.asarray(root[name][:])
            got = f[name][()]
            assert got.dtype == want.dtype and got.shape == want.shape, name
            np.testing.assert_array_equal(got, want, err_msg=name)
            assert f[name].attrs["unit"] == root[name].attrs["unit"], name
            assert [n.decode() if isinstance(n, bytes) else n for n in f[name].attrs["names"]] == \
                root[name].attrs["names"], name
            assert list(f[name].attrs["shape"]) == list(want.shape[1:]), name
        attrs = dict(root.attrs)
        assert json.loads(f.attrs["store_attrs"]) == json.loads(json.dumps(attrs, default=str))
        assert f.attrs["robot"] == attrs["robot"] and f.attrs["n"] == attrs["n"]
        body = {k: (list(v) if not isinstance(v, str) else v) for k, v in f["body"].attrs.items()}
    _assert_body_is_the_models(store, body)


def _assert_body_is_the_models(store, body):
    """The exported body spec is the one `bodyschema train` gives a model of this store (its latent scaling)."""
    from bodyschema.training.data import load_dataset

    spec = load_dataset(store, "ee_xyz").body.to_dict()
    assert body["robot"] == spec["robot"]
    assert [str(n) for n in body["joint_names"]] == spec["joint_names"]
    np.testing.assert_allclose(body["q_low"], spec["q_low"]), np.testing.assert_allclose(body["q_high"], spec["q_high"])


def test_an_existing_output_is_kept_unless_overwrite(stores, tmp_path):
    out = tmp_path / "d.h5"
    export_dataset(stores["babble"], out, "hdf5")
    with pytest.raises(FileExistsError, match="OUT must be a path that does not exist yet.*--overwrite"):
        export_dataset(stores["uniform"], out, "hdf5")
    with h5py.File(out, "r") as f:
        assert f["q"].shape[0] == 150
    export_dataset(stores["uniform"], out, "hdf5", overwrite=True)
    with h5py.File(out, "r") as f:
        assert f["q"].shape[0] == 40
    assert sorted(p.name for p in tmp_path.iterdir()) == [".d.h5.bodyschema-output.json", "d.h5"]   # no partial


def test_overwrite_keeps_a_file_it_did_not_write(stores, tmp_path):
    out = tmp_path / "d.h5"
    out.write_text("keep me")
    with pytest.raises(FileExistsError, match="OUT must be a previous bodyschema-hdf5 output.*not written by"):
        export_dataset(stores["uniform"], out, "hdf5", overwrite=True)
    assert out.read_text() == "keep me"


def test_an_incomplete_store_is_refused_with_its_problems(stores, tmp_path):
    import shutil

    store = shutil.copytree(stores["uniform"], tmp_path / "broken.zarr")
    root = zarr.open_group(str(store), mode="r+")
    root.attrs["complete"] = False
    with pytest.raises(ValueError, match="STORE must be a complete, valid store.*bodyschema validate"):
        export_dataset(store, tmp_path / "d.h5", "hdf5")
    assert not (tmp_path / "d.h5").exists()


def test_an_unknown_format_names_the_choices(stores, tmp_path):
    with pytest.raises(ValueError, match=r"--to must be one of \('hdf5', 'lerobot'\)"):
        export_dataset(stores["uniform"], tmp_path / "d.x", "csv")
