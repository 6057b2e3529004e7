"""Lineage that MLflow itself shows (issue 24 part 4), read back with MLflow's own client, not our tags: an
evaluation run is an input of the logged model behind the registered version it used and is in that model's runs;
the registered model and the version are described; the pyfunc has a signature and pip can resolve what it needs."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import mlflow
import numpy as np
import pytest
from mlflow import MlflowClient

from bodyschema.evaluation.levels import LevelsConfig, run_levels
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config

NAME = "bodyschema-planar2-ee_xyz-tiny"
SPEC = f"models:/{NAME}@champion"


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory, empty_db, kin_store):
    """A registered tiny model and one levels run of it, in a scratch folder shared by this module's tests (one
    train, one evaluation); → (client, its version, the evaluation run)."""
    from bodyschema.models import kinds
    from tests.training.tiny_model import TINY

    folder = tmp_path_factory.mktemp("lineage")
    shutil.copy(empty_db, folder / "mlflow.db")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        patch.delenv("MLFLOW_TRACKING_URI", raising=False)
        patch.setitem(kinds.KINDS, "tiny", TINY)
        result = train(tiny_config(kin_store, epochs=3))
        summary = run_levels(LevelsConfig(models=(SPEC,), levels=(1,), trials=3, runs=1, multistart=0, plots=False,
                                          progress=False, out=folder / "results" / "levels"))
        client = MlflowClient()
        yield client, client.get_model_version(NAME, result.model_version), client.get_run(summary.run_id)


def test_the_evaluation_run_is_an_input_of_the_versions_logged_model_and_in_its_runs(evaluated):
    client, version, run = evaluated
    model_id = version.source.removeprefix("models:/")           # a sqlite store leaves version.model_id empty
    assert client.get_logged_model(model_id).source_run_id == version.run_id
    inputs = [m.model_id for m in run.inputs.model_inputs]       # and its reference in the run's own experiment
    assert model_id in inputs and len(inputs) == 2
    linked = client.get_logged_model(model_id).metrics               # what the logged model's Runs table lists
    assert {m.key: m.value for m in linked if m.run_id == run.info.run_id} == run.data.metrics != {}
    assert run.data.tags["bodyschema.model.0.version"] == str(version.version)     # the tags stay


def test_the_run_name_and_params_say_what_was_evaluated(evaluated):
    _, version, run = evaluated
    assert run.info.run_name == "levels · tiny · planar2"
    assert run.data.params["models"] == f"{SPEC} v{version.version}"
    assert run.data.params["model_kinds"] == "tiny:ee_xyz"


def test_the_registered_model_and_version_are_described(evaluated):
    client, version, _ = evaluated
    data = version.tags["dataset_sha256"]
    for text in (client.get_registered_model(NAME).description, version.description):
        assert "tiny model of robot planar2 (joints" in text and "→ ee_xyz (B, 3) m" in text and data in text
        assert "joint angles z (B, 2) rad" in text and "(B, 3) m" in text
    assert version.tags["bodyschema.model_sha256"] in version.description
    model_id = version.source.removeprefix("models:/")
    assert client.get_logged_model(model_id).tags["mlflow.note.content"] in version.description


def test_the_pyfunc_has_a_signature_and_resolvable_requirements(evaluated):
    client, version, _ = evaluated
    signature = mlflow.models.get_model_info(SPEC).signature
    assert len(signature.inputs.inputs) == 2 and {c.type.name for c in signature.inputs.inputs} == {"double"}
    assert signature.outputs.inputs[0].shape == (-1, 3)
    assert [p.name for p in signature.params.params] == ["output", "extrapolate"]
    local = Path(mlflow.artifacts.download_artifacts(version.source))
    requirements = (local / "requirements.txt").read_text().split()
    assert requirements and not [r for r in requirements if r.lower().startswith("bodyschema")]
    assert all(re.fullmatch(r"[A-Za-z0-9_.-]+==[0-9][0-9A-Za-z.]*", r) for r in requirements), requirements
    assert {r.split("==")[0] for r in requirements} >= {"torch", "numpy", "mlflow"}
    pyfunc = mlflow.pyfunc.load_model(SPEC)                       # the signature takes every dtype it took before
    z64 = np.array([[0.3, -0.4], [1.0, 0.5]])
    np.testing.assert_allclose(pyfunc.predict(z64.astype(np.float32)), pyfunc.predict(z64), rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(pyfunc.predict(z64.tolist()), pyfunc.predict(z64))


@pytest.mark.slow   # ~25 s for `mlflow models serve` to answer on a busy 2-core machine, ~40 s in all
def test_mlflow_models_serve_answers_with_the_models_prediction(workdir, kin_store):
    """`mlflow models serve -m models:/<name>@champion --env-manager local` on 127.0.0.1: a POST /invocations gives
    what `predict` gives (an MDN: a real kind, which the serving process can load; the test kind is in this one)."""
    import torch

    from bodyschema.models.configs import MDNConfig
    from bodyschema.training.config import TrainConfig
    from bodyschema.training.registry import load

    result = train(TrainConfig(model=MDNConfig(epochs=2, hidden=(16,)), data=kin_store, modality="ee_xyz",
                               progress=False))
    uri = f"models:/{result.registered_name}@champion"
    z = [[0.3, -0.4], [1.0, 0.5]]                                            # (2, 2) rad
    want = load(uri).predict(torch.tensor(z, dtype=torch.float64)).numpy()   # (2, 3) m
    with _served(uri, workdir) as url:
        got = _post(f"{url}/invocations", {"inputs": z})["predictions"]
        jacobian = _post(f"{url}/invocations", {"inputs": z, "params": {"output": "jacobian"}})["predictions"]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)       # JSON carries float64 to ~1e-16 relative
    assert np.shape(jacobian) == (2, 3, 2)


@contextlib.contextmanager
def _served(uri: str, folder: Path, startup_s: float = 120.0):
    """`mlflow models serve` of `uri` on a free loopback port, from this environment; stopped (its process group)
    on exit."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    bin_dir = Path(sys.executable).parent                      # mlflow runs `uvicorn` by name: put ours on PATH
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
           "MLFLOW_TRACKING_URI": f"sqlite:///{folder / 'mlflow.db'}"}
    log = (folder / "serve.log").open("w")
    proc = subprocess.Popen([str(bin_dir / "mlflow"), "models", "serve", "-m", uri, "--env-manager", "local",
                             "-h", "127.0.0.1", "-p", str(port)], env=env, cwd=folder, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + startup_s
        while not _pings(url):
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"mlflow models serve did not start: {(folder / 'serve.log').read_text()[-2000:]}")
            time.sleep(0.5)
        yield url
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
        log.close()


def _pings(url: str) -> bool:
    try:
        with urllib.request.urlopen(f"{url}/ping", timeout=2) as response:
            return response.status == 200
    except OSError:
        return False


def _post(url: str, body: dict) -> dict:
    request = urllib.request.Request(url, json.dumps(body).encode(), {"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as response:
        return json.loads(response.read())
