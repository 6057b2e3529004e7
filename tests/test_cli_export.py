"""`bodyschema show` and `bodyschema export dataset|onnx` through the CLI's error boundary: outputs, exit codes."""

from __future__ import annotations

import json

import pytest
import torch

from bodyschema.cli import main
from tests.datagen.export_stores import babble_store, uniform_store

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stores")
    return {"babble": babble_store(folder), "uniform": uniform_store(folder)}


def test_show_prints_the_summary_and_writes_the_sheet_beside_the_store(stores, capsys):
    assert main(["show", str(stores["babble"])]) == 0
    out = capsys.readouterr().out
    sheet = stores["babble"].parent / "babble_contact_sheet.png"
    assert "valid" in out and f"contact sheet: {sheet}" in out and sheet.read_bytes().startswith(PNG)


def test_show_without_images_gives_the_summary_and_says_why_there_is_no_sheet(stores, capsys, tmp_path):
    assert main(["show", str(stores["uniform"]), "--out", str(tmp_path / "s.png")]) == 0
    captured = capsys.readouterr()
    assert "uniform.zarr" in captured.out and "no images" in captured.err and not (tmp_path / "s.png").exists()


def test_show_a_missing_store_is_a_house_error(tmp_path, capsys):
    assert main(["show", str(tmp_path / "nope.zarr")]) == 2
    assert "STORE must be an existing .zarr store" in capsys.readouterr().err


@pytest.mark.parametrize("to", ["hdf5", "lerobot"])
def test_export_dataset_writes_and_refuses_to_overwrite(stores, tmp_path, capsys, to):
    pytest.importorskip("h5py"), pytest.importorskip("pyarrow")
    out = tmp_path / "x"
    assert main(["export", "dataset", "--to", to, str(stores["babble"]), str(out)]) == 0
    assert out.exists() and f"{to}: {out}" in capsys.readouterr().out
    assert main(["export", "dataset", "--to", to, str(stores["babble"]), str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export", "dataset", "--to", to, "--overwrite", str(stores["babble"]), str(out)]) == 0


def test_export_onnx_of_a_trusted_directory_reports_opset_and_error(tmp_path, capsys):
    pytest.importorskip("onnxruntime"), pytest.importorskip("onnxscript")
    from bodyschema.models.mdn import MDNModel
    from bodyschema.models.scaling import BodySpec

    body = BodySpec("toy", ("a", "b"), (-1.0, -1.0), (1.0, 1.0))
    q = torch.rand(40, 2, generator=torch.Generator().manual_seed(0)) * 2 - 1
    MDNModel(body, "ee_xyz", (3,), hidden=(8,), epochs=2).fit(q, torch.cat([q, q.sum(1, True)], 1),
                                                              progress=False).save(tmp_path / "model")
    out = tmp_path / "m.onnx"
    assert main(["export", "onnx", f"trusted:{tmp_path / 'model'}", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "opset 18" in printed and "max |error|" in printed and out.is_file()
    error = float(printed.split("max |error| ")[1].split()[0])
    assert error < 1e-5
    from bodyschema.models.onnx_export import read_metadata
    assert json.loads(read_metadata(out)["bodyschema.body"])["joint_names"] == ["a", "b"]


def test_export_onnx_of_a_kind_without_a_graph_is_a_house_error(tmp_path, capsys):
    assert main(["export", "onnx", "analytic:planar2:ee_xyz", str(tmp_path / "a.onnx")]) == 2
    assert "model kind must be one of" in capsys.readouterr().err


def test_a_train_run_directory_stands_for_its_model(tmp_path):
    from bodyschema.export_commands import model_dir_of_run

    single, multi = tmp_path / "mdn-ee_xyz-1a2b", tmp_path / "multimodal-ee_xyz+image-3c4d"
    for folder in (single / "model", multi / "model-ee_xyz", multi / "model-image"):
        folder.mkdir(parents=True)
        (folder / "meta.json").write_text("{}")
    assert model_dir_of_run(str(single)) == str(single / "model")
    assert model_dir_of_run(f"trusted:{single}") == f"trusted:{single / 'model'}"
    assert model_dir_of_run(str(single / "model")) == str(single / "model")          # a model directory as it is
    assert model_dir_of_run("models:/x@champion") == "models:/x@champion"
    with pytest.raises(ValueError, match=r"MODEL must be one model.*Name one: .*model-ee_xyz, .*model-image"):
        model_dir_of_run(str(multi))
