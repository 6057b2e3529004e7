"""Train, register and load through a real `mlflow server` on 127.0.0.1 (sqlite backend, proxied artifacts)."""

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
import torch
from mlflow import MlflowClient

from bodyschema.training.registry import load, tracking_uri
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config

STARTUP_S = 90     # the first start creates the sqlite tables (several seconds on a busy machine)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def mlflow_server(tmp_path, empty_db):
    """A `mlflow server` bound to 127.0.0.1 on a free port; yields its URL and artifact root, then stops it."""
    db = tmp_path / "server.db"
    db.write_bytes(empty_db.read_bytes())
    artifacts = tmp_path / "server-artifacts"
    port = _free_port()
    mlflow_cli = Path(sys.executable).with_name("mlflow")
    log = (tmp_path / "server.log").open("w")
    proc = subprocess.Popen([str(mlflow_cli), "server", "--host", "127.0.0.1", "--port", str(port), "--workers", "1",
                             "--backend-store-uri", f"sqlite:///{db}", "--artifacts-destination", str(artifacts)],
                            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + STARTUP_S
        while True:
            try:
                with urllib.request.urlopen(f"{url}/health", timeout=2) as response:
                    if response.status == 200:
                        break
            except OSError:
                pass
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"mlflow server did not start: {(tmp_path / 'server.log').read_text()[-2000:]}")
            time.sleep(0.5)
        yield url, artifacts
    finally:
        os.killpg(proc.pid, signal.SIGTERM)     # the server and the workers it started, by its process group
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        log.close()


@pytest.mark.slow   # ~45 s to start the server on a busy 2-core machine, ~75 s in all
def test_train_register_and_load_through_a_tracking_server(mlflow_server, kin_store, tiny_kind, tmp_path,
                                                           monkeypatch):
    url, artifacts = mlflow_server
    monkeypatch.setenv("MLFLOW_TRACKING_URI", url)
    monkeypatch.chdir(tmp_path)
    assert tracking_uri() == url
    result = train(tiny_config(kin_store, epochs=4))
    assert result.model_version == "1" and result.champion
    assert MlflowClient(url).get_run(result.run_id).info.status == "FINISHED"
    assert list(artifacts.rglob("state.pt")), "artifacts went to the server's artifact store"
    assert not (tmp_path / "mlflow.db").exists() and not (tmp_path / "mlartifacts").exists()

    model = load(f"models:/{result.registered_name}@champion")
    from bodyschema.models import load_model

    z = torch.zeros(3, 2, dtype=torch.float64)
    torch.testing.assert_close(model.predict(z), load_model(result.model_dir).predict(z), rtol=0, atol=0)
    import mlflow  # the pyfunc's loader finds the recorded digest through the server too

    pyfunc = mlflow.pyfunc.load_model(f"models:/{result.registered_name}@champion")
    torch.testing.assert_close(torch.as_tensor(pyfunc.predict(z.numpy(), params={"output": "jacobian"})),
                               model.jacobian(z), rtol=0, atol=0)
