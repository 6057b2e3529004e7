"""Fixtures of the training tests: small real dataset stores (from datagen), a fresh MLflow store per test."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from bodyschema.models import kinds


@pytest.fixture(scope="session")
def kin_store(tmp_path_factory) -> Path:
    """planar2, uniform poses, kinematics only (q, ee_xyz, ee_pixel, jacobian): 400 samples, 4 chunks."""
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    out = tmp_path_factory.mktemp("stores") / "kin.zarr"
    return generate(DatagenConfig(robot="planar2", n=400, images=False, out=out, shard_size=100, seed=0),
                    progress=False)


@pytest.fixture(scope="session")
def image_store(tmp_path_factory) -> Path:
    """planar2, babbling episodes (2 s each), 16×16 grayscale images: 320 samples."""
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    out = tmp_path_factory.mktemp("stores") / "img.zarr"
    return generate(DatagenConfig(robot="planar2", n=320, sampler="babble", images=True, image_size=(16, 16),
                                  episode_s=2.0, out=out, shard_size=80, seed=0), progress=False)


@pytest.fixture(scope="session")
def empty_db(tmp_path_factory) -> Path:
    """An initialised, empty MLflow sqlite store (creating the tables takes seconds; copying it does not)."""
    from mlflow import MlflowClient

    path = tmp_path_factory.mktemp("db") / "mlflow.db"
    MlflowClient(f"sqlite:///{path}").search_experiments()
    return path


@pytest.fixture
def workdir(tmp_path, monkeypatch, empty_db) -> Path:
    """cwd = a fresh tmp dir holding a copy of the empty MLflow store; MLFLOW_TRACKING_URI unset (the default)."""
    shutil.copy(empty_db, tmp_path / "mlflow.db")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    return tmp_path


@pytest.fixture
def tiny_kind(monkeypatch):
    """Make the test model kind "tiny" trainable."""
    from tests.training.tiny_model import TINY, TinyModel

    monkeypatch.setitem(kinds.KINDS, "tiny", TINY)

    monkeypatch.setattr(TinyModel, "fail_at", -1)
    return TinyModel

