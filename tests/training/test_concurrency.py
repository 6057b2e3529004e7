"""Two processes, kills and re-runs: each defect of issue 12 (concurrency and leftovers) as it was found.

Processes are real (`python -m tests.training.run_train`) where a kill or a second process is the point."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mlflow import MlflowClient

from bodyschema.base.locks import Locked
from bodyschema.training.champion import update_champion
from bodyschema.training.digest import DIGEST_TAG
from bodyschema.training.registry import load
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config

REPO = Path(__file__).resolve().parents[2]
NAME = "bodyschema-planar2-ee_xyz-tiny"
START_S = 90          # a fresh Python importing torch + mlflow on a busy 2-core machine


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}   # the default store of the cwd
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env


def _spawn(cwd: Path, config: dict, **spec) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "tests.training.run_train", json.dumps({"config": config, **spec})],
                            cwd=cwd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_checkpoint(cwd: Path, proc: subprocess.Popen) -> Path:
    """The run directory of `proc` once its first checkpoint exists (it is then fitting)."""
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        found = list((cwd / "runs").glob("*/checkpoint.pt"))
        if found and (found[0].parent / "mlflow_run_id").is_file():
            return found[0].parent
        if proc.poll() is not None:
            pytest.fail(f"training process ended early: {proc.communicate()[1][-2000:]}")
        time.sleep(0.2)
    proc.kill()
    pytest.fail("no checkpoint within the start-up time")


def _client(workdir: Path) -> MlflowClient:
    uri = f"sqlite:///{workdir / 'mlflow.db'}"
    return MlflowClient(uri, uri)         # registry too: its default is the last store this process used


def _config(kin_store: Path, epochs: int) -> dict:
    return {"data": str(kin_store), "epochs": epochs}


@pytest.mark.slow     # two fresh interpreters creating the tables: ~30 s on a busy 2-core machine
def test_two_processes_creating_the_tracking_database_both_succeed(tmp_path):
    """(a) Before: one of them died in the sqlite schema migration ("duplicate column name")."""
    uri = f"sqlite:///{tmp_path / 'fresh' / 'mlflow.db'}"
    (tmp_path / "fresh").mkdir()
    code = ("import sys; from bodyschema.training.registry import use_tracking, ensure_experiment; "
            "use_tracking(sys.argv[1]); print(ensure_experiment('bodyschema'))")
    procs = [subprocess.Popen([sys.executable, "-c", code, uri], cwd=tmp_path, env=_env(), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=START_S) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err[-1500:] for _, err in outs]
    assert len({out.strip() for out, _ in outs}) == 1, "both see the same experiment"


def _tables(db: Path) -> int:
    """How many tables a sqlite file holds right now (0 while it is missing or locked)."""
    import sqlite3

    if not db.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=0.01) as con:
            return con.execute("SELECT count(*) FROM sqlite_master WHERE type = 'table'").fetchone()[0]
    except sqlite3.Error:
        return 0


def test_a_creation_killed_half_way_leaves_nothing_the_next_process_trips_on(tmp_path):
    """(a, kill) Before: kill -9 while MLflow created its tables left a half-built mlflow.db; every later command
    died on "table ... already exists". Now the store is built as mlflow.db.creating and renamed when complete."""
    from bodyschema.training.registry import use_tracking

    db = tmp_path / "mlflow.db"
    code = "import sys; from bodyschema.training.registry import use_tracking; use_tracking(sys.argv[1])"
    proc = subprocess.Popen([sys.executable, "-c", code, f"sqlite:///{db}"], cwd=tmp_path, env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + START_S
    while _tables(db) + _tables(db.with_name("mlflow.db.creating")) < 3:      # kill half-way through the tables
        assert proc.poll() is None and time.monotonic() < deadline, "the creating process ended early"
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not db.exists(), "no half-built mlflow.db (MLflow would re-run a migration on it and fail)"
    client = use_tracking(f"sqlite:///{db}")
    assert client.search_experiments() and client.search_registered_models() == []
    assert not list(tmp_path.glob("*.creating*"))


def test_the_same_command_started_twice_is_refused_naming_the_first_pid(workdir, kin_store, tiny_kind):
    """(b) Before: the second attached to the first's RUNNING run and crashed on its checkpoint."""
    first = _spawn(workdir, _config(kin_store, 60), sleep_s=0.5)
    try:
        run_dir = _wait_for_checkpoint(workdir, first)
        refused = rf"run directory .*{run_dir.name} must be free .* Got 'locked by pid {first.pid}'"
        with pytest.raises(Locked, match=refused):
            train(tiny_config(kin_store, epochs=60))
        assert first.poll() is None, "the first one goes on undisturbed"
    finally:
        first.kill()
        first.wait()


def test_a_killed_run_is_marked_killed_by_the_next_command_and_then_resumed(workdir, kin_store, tiny_kind):
    """(e) Before: a run whose process was killed stayed RUNNING for ever."""
    first = _spawn(workdir, _config(kin_store, 30), sleep_s=0.3)
    run_dir = _wait_for_checkpoint(workdir, first)
    run_id = (run_dir / "mlflow_run_id").read_text()
    first.send_signal(signal.SIGKILL)
    first.wait()
    client = _client(workdir)
    assert client.get_run(run_id).info.status == "RUNNING", "what kill -9 leaves behind"

    train(tiny_config(kin_store, epochs=2))                # any other train in the experiment
    assert client.get_run(run_id).info.status == "KILLED"
    assert "found dead" in client.get_run(run_id).data.tags["bodyschema.ended"]

    resumed = train(tiny_config(kin_store, epochs=30))     # the same config continues that run
    assert resumed.run_id == run_id and client.get_run(run_id).info.status == "FINISHED"
    steps = [m.step for m in client.get_metric_history(run_id, "train_loss")]
    assert steps[-1] == 29 and len(steps) == len(set(steps)), "resumed from the checkpoint: no epoch twice"


@pytest.mark.parametrize("leftover", ["as-now", "untagged"])
def test_a_kill_right_after_creating_the_version_converges_to_one_loadable_champion(workdir, kin_store, tiny_kind,
                                                                                     leftover):
    """(c) Before: a kill between "Created version N" and its tags left a version without digest, never loadable.
    Now the tags are written with the version; "untagged" replays the old leftover, which the resume removes."""
    proc = _spawn(workdir, _config(kin_store, 3), kill_after_version=True)
    proc.communicate(timeout=START_S)
    assert proc.returncode == -signal.SIGKILL
    client = _client(workdir)
    (created,) = client.search_model_versions(f"name = '{NAME}'")
    assert DIGEST_TAG in created.tags, "tags are part of the version's creation"
    if leftover == "untagged":
        client.delete_model_version_tag(NAME, created.version, DIGEST_TAG)

    result = train(tiny_config(kin_store, epochs=3))
    versions = client.search_model_versions(f"name = '{NAME}'")
    assert all(DIGEST_TAG in v.tags for v in versions) and len(versions) == 1
    assert result.champion and result.run_id == created.run_id, "the killed run was completed, not duplicated"
    assert str(client.get_model_version_by_alias(NAME, "champion").version) == result.model_version
    load(f"models:/{NAME}@champion")


def test_a_finished_command_run_again_reuses_its_version(workdir, kin_store, tiny_kind):
    """(d) Before: every re-run of a finished `train` registered one more, identical, version."""
    first = train(tiny_config(kin_store, epochs=5))
    again = train(tiny_config(kin_store, epochs=5))
    assert again.reused and not first.reused and "reusing its registered versions" in str(again)
    assert (again.run_id, again.model_version, again.champion) == (first.run_id, first.model_version, True)
    assert again.metrics["val_rmse"] == first.metrics["val_rmse"]
    client = _client(workdir)
    assert len(client.search_model_versions(f"name = '{NAME}'")) == 1
    assert len(client.search_runs([client.get_experiment_by_name("bodyschema").experiment_id])) == 1

    shutil.rmtree(workdir / "runs")          # its run directory gone: trained again, same weights, same version
    third = train(tiny_config(kin_store, epochs=5))
    assert third.run_id != first.run_id and third.model_version == first.model_version
    assert len(client.search_model_versions(f"name = '{NAME}'")) == 1


def test_two_runs_finishing_together_leave_the_better_one_champion(workdir, kin_store, tiny_kind, monkeypatch):
    """(f) Before: update_champion read the alias, then set it; the slower, worse run could overwrite the better."""
    better, worse = (train(tiny_config(kin_store, epochs=e)) for e in (40, 2))
    assert better.metrics["val_rmse"] < worse.metrics["val_rmse"]
    client = _client(workdir)
    client.delete_registered_model_alias(NAME, "champion")
    read = MlflowClient.get_model_version_by_alias

    def slow_read(self, *args):                 # widen the read → set window, as a busy machine does
        try:
            return read(self, *args)
        finally:
            time.sleep(0.6)

    monkeypatch.setattr(MlflowClient, "get_model_version_by_alias", slow_read)
    outcome = {}

    def finish(result, delay):
        time.sleep(delay)
        outcome[result.model_version] = update_champion(_client(workdir), NAME, result.model_version,
                                                        result.metrics["val_rmse"])

    threads = [threading.Thread(target=finish, args=(better, 0.0)), threading.Thread(target=finish, args=(worse, 0.2))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    monkeypatch.undo()
    assert str(client.get_model_version_by_alias(NAME, "champion").version) == better.model_version
    assert outcome == {better.model_version: True, worse.model_version: False}


def test_check_tracking_refuses_unknown_schemes_and_servers_that_do_not_answer(tmp_path):
    import http.server
    import socket

    from bodyschema.training.registry import TrackingUnreachable, check_tracking, use_tracking

    for uri in ("notascheme://x", "sqlite3:///x.db", ""):
        with pytest.raises(ValueError, match="tracking URI must be"):
            check_tracking(uri)
    with pytest.raises(ValueError, match="tracking URI must be"):
        use_tracking("notascheme://x")
    for uri in (f"sqlite:///{tmp_path}/x.db", f"file://{tmp_path}/mlruns", str(tmp_path)):
        check_tracking(uri)                                            # known schemes; nothing is contacted

    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    with pytest.raises(TrackingUnreachable, match=rf"tracking server must be answering within 2 s. Got .*:{port}"):
        check_tracking(f"http://127.0.0.1:{port}", timeout_s=2)      # nothing listens: refused at once

    with socket.socket() as silent:                                    # accepts connections, never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        start = time.monotonic()
        with pytest.raises(TrackingUnreachable) as info:
            check_tracking(f"http://127.0.0.1:{silent.getsockname()[1]}", timeout_s=0.5)
        assert time.monotonic() - start < 5 and isinstance(info.value, ConnectionError)

    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.BaseHTTPRequestHandler)   # answers 501
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        check_tracking(f"http://127.0.0.1:{server.server_address[1]}", timeout_s=5)   # an answer, even an error
    finally:
        server.shutdown()
        server.server_close()

