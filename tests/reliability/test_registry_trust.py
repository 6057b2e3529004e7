"""Round 3 (issue 25), the model registry's trust boundary and MLflow edge cases.

- A loader checks the files against the tracking database's record of the model asked for (the version in the
  URI), never against ids read from the MLmodel file the artifact store holds; `registry.load` never imports
  what an MLmodel names, while `mlflow.pyfunc.load_model` does (MLflow's design, documented in the README).
- `load_model(dir)` refuses a state.pt whose bytes differ from the checksum its save recorded.
- Bad tracking URIs are the house error at once; a full disk leaves no temporary and says "disk full".
- A digest mismatch names the version and both digests; "Created version" shows only with --verbose.
"""

from __future__ import annotations

import contextlib
import errno
import importlib.util
import json
import logging
import shutil
import sys
from pathlib import Path

import mlflow
import pytest
import torch
import yaml
from mlflow import MlflowClient

from bodyschema import log
from bodyschema.errors import explain
from bodyschema.models import BodySpec, load_model
from bodyschema.training.champion import promote
from bodyschema.training.registry import load, use_tracking
from bodyschema.training.train import train
from tests.limits import file_size_limit
from tests.test_cli_fuzz import build_world, run_and_check, run_in_process
from tests.training.tiny_model import TinyModel, tiny_config

NAME = "bodyschema-planar2-ee_xyz-tiny"
BODY = BodySpec("planar2", ("shoulder", "elbow"), (-1.0, -1.0), (1.0, 1.0))


# ---- helpers ---------------------------------------------------------------------------------------------


def artifact_dir(version) -> Path:
    """The stored copy of a version's logged model (a local artifact store: the files themselves)."""
    return Path(mlflow.artifacts.download_artifacts(version.source))


def tiny_model(seed: int = 0) -> TinyModel:
    q = torch.rand(40, 2, generator=torch.Generator().manual_seed(seed), dtype=torch.float64) * 2 - 1
    return TinyModel(BODY, "ee_xyz", (3,), epochs=3).fit(q, torch.cat([q, q[:, :1]], dim=1))


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def one_version(workdir, kin_store, tiny_kind):
    """Version 1 of NAME, champion; → its ModelVersion."""
    train(tiny_config(kin_store, epochs=4))
    return MlflowClient().get_model_version(NAME, "1")


@pytest.fixture
def two_versions(workdir, kin_store, tiny_kind):
    """Versions 1 and 2 of NAME (different weights), version 1 champion; → their ModelVersions."""
    train(tiny_config(kin_store, epochs=4))
    train(tiny_config(kin_store, epochs=9))
    promote(NAME, 1)
    client = MlflowClient()
    return client.get_model_version(NAME, "1"), client.get_model_version(NAME, "2")


# ---- 1. the artifact store cannot choose what loads ---------------------------------------------------------
def test_another_models_folder_swapped_in_is_refused_on_every_route(two_versions):
    """Before: the pyfunc loader looked the digest up by the model_id in the (swapped) MLmodel: it returned v2."""
    v1, v2 = two_versions
    stored = artifact_dir(v1)
    shutil.rmtree(stored)
    shutil.copytree(artifact_dir(v2), stored)                   # v2's files, MLmodel included, in v1's place
    routes = [f"models:/{NAME}/1", f"models:/{NAME}@champion", v1.source, f"runs:/{v1.run_id}/model"]
    for uri in routes:
        with pytest.raises(ValueError, match=r"sha256 of the files of .* must be .*refusing to load"):
            mlflow.pyfunc.load_model(uri)
    with pytest.raises(ValueError, match=rf"sha256 of the files of models:/{NAME}/1 must be"):
        load(f"models:/{NAME}@champion")
    assert mlflow.pyfunc.load_model(f"models:/{NAME}/2").get_raw_model().weight_.shape == (64, 3)   # v2 as v2


def test_a_model_reached_by_path_must_be_recorded_in_the_tracking_store(one_version, tmp_path):
    copy = shutil.copytree(artifact_dir(one_version), tmp_path / "copy")
    assert mlflow.pyfunc.load_model(str(copy)).predict(torch.zeros(1, 2).numpy()).shape == (1, 3)
    model_dir = copy / yaml.safe_load((copy / "MLmodel").read_text())["flavors"]["python_function"]["data"]
    edited = load_model(model_dir)
    edited.weight_ = edited.weight_ + 1.0
    edited.save(model_dir)                                       # well-formed, consistent, recorded nowhere
    with pytest.raises(ValueError, match="recorded nowhere"):
        mlflow.pyfunc.load_model(str(copy))


def test_registry_load_never_imports_what_an_edited_mlmodel_names(one_version, tmp_path):
    stored, marker, module = artifact_dir(one_version), tmp_path / "payload-ran", "bodyschema_test_payload"
    (stored / "code").mkdir()
    (stored / "code" / f"{module}.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\n")
    mlmodel = yaml.safe_load((stored / "MLmodel").read_text())
    mlmodel["flavors"]["python_function"].update(loader_module=module, code="code")
    (stored / "MLmodel").write_text(yaml.safe_dump(mlmodel))

    assert load(f"models:/{NAME}/1").predict(torch.zeros(1, 2, dtype=torch.float64)).shape == (1, 3)
    assert not marker.exists(), "registry.load ran code named by the MLmodel file"

    # The documented limit (README, Security and trust): MLflow imports what the MLmodel names, by design.
    path_before = list(sys.path)
    try:
        with contextlib.suppress(Exception):
            mlflow.pyfunc.load_model(f"models:/{NAME}/1")
        assert marker.exists(), "MLflow no longer runs MLmodel-named code: update the README's security section"
    finally:
        sys.modules.pop(module, None)
        sys.path[:] = path_before


# ---- 1c. integrity of state.pt --------------------------------------------------------------------------
def test_load_model_refuses_flipped_weights(tmp_path, tiny_kind):
    """Before: a flipped byte inside a weight tensor loaded as a different model, silently."""
    model = tiny_model()
    model.save(tmp_path / "m")
    state = tmp_path / "m" / "state.pt"
    data = bytearray(state.read_bytes())
    at = bytes(data).index(model.weight_.numpy().tobytes()) + 8 * 10 + 3     # inside the 11th float64 weight
    data[at] ^= 0x10
    state.write_bytes(bytes(data))
    assert torch.load(state, weights_only=True)["weight"].ne(model.weight_).sum() == 1, "premise: one weight moved"
    with pytest.raises(ValueError, match=r"the sha256 of .*state.pt must be .* \(recorded in meta.json") as info:
        load_model(tmp_path / "m")
    assert "being read" not in explain(info.value)


def test_a_model_saved_before_the_checksum_still_loads(tmp_path, tiny_kind):
    model = tiny_model()
    model.save(tmp_path / "m")
    meta = json.loads((tmp_path / "m" / "meta.json").read_text())
    del meta["state_sha256"]
    (tmp_path / "m" / "meta.json").write_text(json.dumps(meta))
    z = torch.zeros(2, 2, dtype=torch.float64)
    torch.testing.assert_close(load_model(tmp_path / "m").predict(z), model.predict(z), rtol=0, atol=0)


# ---- 3. full disk ---------------------------------------------------------------------------------------
def test_a_checkpoint_that_does_not_fit_leaves_the_previous_one_and_no_temporary(tmp_path):
    from bodyschema.models._nn_fit import _save_checkpoint

    net = torch.nn.Linear(32, 32)
    opt, gen = torch.optim.Adam(net.parameters()), torch.Generator().manual_seed(0)
    path = tmp_path / "run" / "checkpoint.pt"
    _save_checkpoint(path, {"epoch": 0}, net, opt, gen, "f")
    before = path.read_bytes()
    opt.step()                                                   # Adam's state grows the next checkpoint
    with file_size_limit(len(before) // 2), pytest.raises(OSError) as info:
        _save_checkpoint(path, {"epoch": 1}, net, opt, gen, "f")
    assert info.value.errno == errno.EFBIG and info.value.filename == str(path)
    assert path.read_bytes() == before and sorted(p.name for p in path.parent.iterdir()) == ["checkpoint.pt"]
    line = explain(info.value)
    assert "free space" in line and str(path.parent) in line and "being read" not in line


def test_a_model_save_that_does_not_fit_changes_nothing(tmp_path, tiny_kind):
    tiny_model(seed=0).save(tmp_path / "m")
    before = files_of(tmp_path / "m")
    with file_size_limit(len(before["meta.json"]) + 64), pytest.raises(OSError) as info:
        tiny_model(seed=1).save(tmp_path / "m")
    assert info.value.errno == errno.EFBIG and info.value.filename.endswith("state.pt")
    assert files_of(tmp_path / "m") == before, "the previous save is intact and no temporary is left"


def test_creating_the_tracking_database_on_a_full_disk_leaves_nothing(tmp_path, monkeypatch):
    """Before: `registry list` left mlflow.db.creating and printed sqlalchemy's traceback."""
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)        # use_tracking exports it; restored after
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    with file_size_limit(64 * 1024), pytest.raises(OSError) as info:
        use_tracking(uri)
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "mlflow.db")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mlflow.db.lock"], "no database, no .creating file"
    assert "free space" in explain(info.value)


def test_train_on_a_full_disk_says_so_and_leaves_no_temporary(in_world, capsys, monkeypatch):
    """Before: `train` left checkpoint.pt.tmp and blamed "a file being read"."""
    from bodyschema.models import files

    real_open = open

    def full_disk(path, mode="r", *args, **kwargs):
        handle = real_open(path, mode, *args, **kwargs)
        if "w" in mode and str(path).endswith("checkpoint.pt.tmp"):
            handle.write(b"partial")
            handle.close()
            raise OSError(errno.ENOSPC, "No space left on device")
        return handle

    monkeypatch.setattr(files, "open", full_disk, raising=False)
    code, err = run_in_process(f"train mdn --data {in_world}/good.zarr --epochs 2 --no-progress".split(), capsys)
    assert code == 2 and "Traceback" not in err, err
    assert "checkpoint.pt must be written to a disk with free space" in err and "being read" not in err, err
    assert not [p for p in in_world.rglob("*.tmp")], "a temporary was left behind"


# ---- 4. messages ----------------------------------------------------------------------------------------
def test_a_digest_mismatch_names_the_version_and_both_digests(one_version):
    (state,) = artifact_dir(one_version).rglob("state.pt")
    state.write_bytes(state.read_bytes() + b"\0")
    with pytest.raises(ValueError) as info:
        load(f"models:/{NAME}/1")
    line, expected = explain(info.value), one_version.tags["bodyschema.model_sha256"]
    assert f"models:/{NAME}/1" in line and expected[:16] in line and "refusing to load" in line
    assert "being read" not in line and "complete" not in line


@pytest.mark.parametrize("verbosity, shown", [(log.QUIET, False), (log.NORMAL, False), (log.VERBOSE, True)])
def test_created_version_is_a_debug_line_shown_only_verbose(verbosity, shown, workdir, kin_store, tiny_kind,
                                                           capsys, monkeypatch):
    for name in (*log.MLFLOW_QUIET_ENV, "TQDM_DISABLE"):
        monkeypatch.delenv(name, raising=False)              # configure() sets them; restored after the test
    monkeypatch.setattr(logging.getLogger(log.LOGGER), "level", logging.getLogger(log.LOGGER).level)
    log.configure(verbosity)
    train(tiny_config(kin_store, epochs=3))
    err = capsys.readouterr().err
    assert ("Created version '1'" in err) is shown, err


# ---- 2. bad tracking URIs, through the CLI (the fuzz harness of tests/test_cli_fuzz.py) -------------------
CASES = [      # (id, command) as in tests/test_cli_fuzz.py; bench/probe.py runs them through the console script
    ("registry-list-sqlite-folder", "registry list --tracking-uri sqlite:///{W}/good.zarr"),
    ("registry-list-sqlite-text-file", "registry list --tracking-uri sqlite:///{W}/good.zarr/zarr.json"),
    ("registry-list-sqlite-no-folder", "registry list --tracking-uri sqlite:///{W}/nowhere/mlflow.db"),
    ("registry-promote-sqlite-folder", "registry promote bodyschema-x 1 --tracking-uri sqlite:///{W}/notastore"),
    ("train-sqlite-text-file", "train gpr --data {W}/good.zarr --tracking-uri sqlite:///{W}/img.zarr/zarr.json"),
    ("levels-registry-sqlite-folder", "evaluate levels --model models:/bodyschema-x@champion --no-mlflow "
                                      "--tracking-uri sqlite:///{W}/good.zarr --out {W}/res"),
    ("registry-list-unknown-driver", "registry list --tracking-uri mysql+nodriver://u@127.0.0.1/db"),
    ("registry-list-mysql-no-driver", "registry list --tracking-uri mysql://u:secret@127.0.0.1/db"),
    ("registry-list-postgresql-no-driver", "registry list --tracking-uri postgresql://u@127.0.0.1/db"),
]
DRIVER_CASES = {"registry-list-mysql-no-driver": "MySQLdb", "registry-list-postgresql-no-driver": "psycopg"}


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    return build_world(tmp_path_factory.mktemp("registry-fuzz"))


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_tracking_uri_is_a_clear_error_at_once(case_id, command, in_world, capsys):
    """Before: a folder took 106 s of retries then a traceback; a text file or a missing driver, a traceback."""
    if case_id in DRIVER_CASES and importlib.util.find_spec(DRIVER_CASES[case_id]) is not None:
        pytest.skip(f"{DRIVER_CASES[case_id]} is installed here")
    err = run_and_check(case_id, command, in_world, capsys)
    assert not [line for line in err.splitlines() if "error:" in line and "secret" in line], "a password shown"
