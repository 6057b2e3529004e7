"""The registry: champion moves only on improvement, promote/list, and `load` refuses what it must refuse."""

import os
import shutil
from pathlib import Path

import mlflow
import pytest
import torch
from mlflow import MlflowClient

from bodyschema.models import BodySpec
from bodyschema.training.champion import promote
from bodyschema.training.digest import DIGEST_TAG
from bodyschema.training.registry import _artifact_dir, list_models, load, tracking_uri
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config

NAME = "bodyschema-planar2-ee_xyz-tiny"


def test_champion_moves_only_when_the_validation_metric_improves(workdir, kin_store, tiny_kind):
    results = [train(tiny_config(kin_store, epochs=e)) for e in (10, 2, 40)]
    rmse = [r.metrics["val_rmse"] for r in results]
    assert rmse[1] > rmse[0] > rmse[2], "the tiny model improves with epochs (premise of this test)"
    assert [r.champion for r in results] == [True, False, True]

    rows = list_models()
    assert [(r.name, r.version, r.aliases) for r in rows] == [(NAME, "1", ()), (NAME, "2", ()),
                                                              (NAME, "3", ("champion",))]
    assert [r.val_rmse for r in rows] == pytest.approx(rmse)
    assert "@champion" in str(rows[2])

    promote(NAME, 2)                      # by hand, whatever the metric says
    assert str(MlflowClient(tracking_uri()).get_model_version_by_alias(NAME, "champion").version) == "2"
    with pytest.raises(ValueError, match="NAME VERSION must be a registered model version"):
        promote(NAME, 9)


@pytest.fixture(scope="module")
def registered(tmp_path_factory, kin_store, empty_db):
    """One registered tiny model in an explicit (not default) tracking store; returns its tracking URI."""
    from bodyschema.models import kinds
    from tests.training.tiny_model import TINY

    root = tmp_path_factory.mktemp("registry")
    shutil.copy(empty_db, root / "mlflow.db")
    uri = f"sqlite:///{root / 'mlflow.db'}"
    before, cwd = kinds.KINDS.get("tiny"), os.getcwd()
    kinds.register(TINY)
    os.chdir(root)                   # the experiment's artifacts go under the working directory: keep them in tmp
    try:
        train(tiny_config(kin_store, epochs=3, tracking_uri=uri, run_root=root / "runs",
                          experiment="registry-tests"))
    finally:
        os.chdir(cwd)
        kinds.KINDS.pop("tiny")
        if before is not None:
            kinds.register(before)
    assert (root / "mlartifacts").is_dir()
    return uri


def test_load_checks_body_and_modality(registered):
    model = load(f"models:/{NAME}/1", tracking=registered)
    z = torch.zeros(2, 2, dtype=torch.float64)
    assert model.predict(z).shape == (2, 3)
    same = BodySpec("planar2", ("shoulder", "elbow"), (-1.0, -1.0), (1.0, 1.0))   # ranges may differ
    load(f"models:/{NAME}@champion", expect_body=same, expect_modality="ee_xyz", tracking=registered)
    with pytest.raises(ValueError, match="registered model models:/.*/1 body must be robot 'nao_arm'"):
        load(f"models:/{NAME}@champion", expect_body=BodySpec("nao_arm", ("a", "b"), (0.0, 0.0), (1.0, 1.0)),
             tracking=registered)
    with pytest.raises(ValueError, match="modality of registered model .* must be 'ee_pixel'. Got 'ee_xyz'"):
        load(f"models:/{NAME}@champion", expect_modality="ee_pixel", tracking=registered)


@pytest.mark.parametrize("uri", ["runs:/abc/model", "models:/x", f"models:/{NAME}@nobody", "models:/nobody/1"])
def test_load_rejects_bad_or_unknown_uris(registered, uri):
    with pytest.raises(ValueError, match="uri must be"):
        load(uri, tracking=registered)


def test_load_refuses_artifacts_that_changed_after_logging(registered):
    source = MlflowClient(registered).get_model_version(NAME, "1").source
    local = mlflow.artifacts.download_artifacts(source, tracking_uri=registered)   # local store: the copy itself
    state = _artifact_dir(Path(local)) / "state.pt"
    original = state.read_bytes()
    try:
        state.write_bytes(original[:-1] + bytes([original[-1] ^ 1]))
        with pytest.raises(ValueError, match="sha256 of the files of .* must be .* refusing to load"):
            load(f"models:/{NAME}/1", tracking=registered)
    finally:
        state.write_bytes(original)
    load(f"models:/{NAME}/1", tracking=registered)       # restored: loads again


def test_load_refuses_a_version_without_a_recorded_digest(registered):
    client = MlflowClient(registered)
    digest = client.get_model_version(NAME, "1").tags[DIGEST_TAG]
    client.delete_model_version_tag(NAME, "1", DIGEST_TAG)
    try:
        with pytest.raises(ValueError, match="must be recorded with a bodyschema.model_sha256 in the tracking"):
            load(f"models:/{NAME}/1", tracking=registered)
    finally:
        client.set_model_version_tag(NAME, "1", DIGEST_TAG, digest)
