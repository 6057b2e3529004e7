"""A mistyped tracking URI is the house error, not a new empty registry: a local store (sqlite file, file: or path
folder) whose folder is missing is refused unless --create; a missing store is refused for commands that read models
(registry list/promote, evaluate with a models:/ spec) and created by those that only write (train, demo)."""

from __future__ import annotations

import shutil

import pytest

from bodyschema import cli, commands
from bodyschema.tracking_check import check_tracking_first
from bodyschema.training.tracking_store import local_store


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    """No tracking URI or debug flag of the caller's environment; the cwd a scratch folder (the default store)."""
    for name in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def files_under(folder) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.parametrize("uri", ["sqlite:///{W}/typo/mlflow.db", "file:{W}/typo/mlruns", "{W}/typo/mlruns"])
def test_a_store_in_a_missing_folder_is_the_house_error_and_creates_nothing(uri, clean_env, capsys):
    uri = uri.format(W=clean_env)
    for argv in (["registry", "list"], ["train", "gpr", "--data", "d.zarr"], ["demo", "--out", "o"]):
        assert cli.main([*argv, "--tracking-uri", uri]) == 2
        line = capsys.readouterr().err.splitlines()[-1]
        assert "error: tracking URI must be a store in an existing folder" in line, line
        assert f"{clean_env / 'typo'} does not exist" in line and "--create" in line, line
    assert files_under(clean_env) == [], "nothing created"


@pytest.mark.parametrize("argv", [["registry", "list"], ["registry", "promote", "bodyschema-x", "1"],
                                  ["evaluate", "levels", "--model", "models:/bodyschema-x@champion", "--no-mlflow",
                                   "--out", "res"],
                                  ["evaluate", "reaching", "--goal", "image", "--encoder",
                                   "models:/bodyschema-x-image-encoder@champion", "--no-mlflow", "--out", "res"]],
                         ids=["list", "promote", "levels", "reaching-encoder"])
def test_a_missing_store_is_the_house_error_for_a_command_that_reads_models(argv, clean_env, capsys):
    """Before: `registry list` on a mistyped file name made an empty mlflow.db and said "no registered models"."""
    assert cli.main([*argv, "--tracking-uri", f"sqlite:///{clean_env}/mlfow.db"]) == 2
    line = capsys.readouterr().err.splitlines()[-1]
    assert "tracking URI must be an existing tracking store (this command reads registered models)" in line, line
    assert f"{clean_env / 'mlfow.db'} does not exist" in line, line
    assert files_under(clean_env) == [], "nothing created"


def test_the_default_store_missing_is_named_for_registry_list(clean_env, capsys):
    assert cli.main(["registry", "list"]) == 2
    err = capsys.readouterr().err
    assert f"tracking: sqlite:///{clean_env / 'mlflow.db'}" in err and "must be an existing tracking store" in err


@pytest.mark.parametrize("argv", [["train", "gpr", "--data", "d.zarr"], ["demo"],
                                  ["evaluate", "levels", "--model", "analytic:nao_arm:ee_xyz"]],
                         ids=["train", "demo", "levels-analytic"])
def test_a_command_that_only_writes_may_create_its_store_in_an_existing_folder(argv, clean_env):
    check_tracking_first(cli.parse_command(argv), commands.find(commands.words_of(argv)))   # passes; made when written
    assert files_under(clean_env) == []


def test_create_makes_the_folder_and_the_store_of_a_command_that_reads(clean_env, capsys):
    uri = f"sqlite:///{clean_env}/new/place/mlflow.db"
    assert cli.main(["--create", "registry", "list", "--tracking-uri", uri]) == 0
    out, err = capsys.readouterr()
    assert out.strip() == "no registered bodyschema models" and f"tracking: {uri}" in err
    assert (clean_env / "new" / "place" / "mlflow.db").is_file()
    assert cli.main(["registry", "list", "--tracking-uri", uri]) == 0, "it exists now: no flag needed"


def test_create_on_a_command_that_does_not_talk_to_mlflow_is_refused(clean_env, capsys):
    assert cli.main(["validate", "x.zarr", "--create"]) == 2
    assert "error: --create must be given to a command that talks to MLflow" in capsys.readouterr().err


def test_servers_and_database_urls_are_no_local_stores():
    for uri in ("http://127.0.0.1:5000", "postgresql://u:p@h/db", "databricks", "sqlite:///:memory:", "sqlite://"):
        assert local_store(uri) is None, uri
    assert str(local_store("sqlite:////abs/mlflow.db")) == "/abs/mlflow.db"
    assert str(local_store("file:///abs/ml%20runs")) == "/abs/ml runs"
    assert str(local_store("mlruns")) == "mlruns"


def test_an_existing_store_passes_unchanged(clean_env, request):
    shutil.copy(request.getfixturevalue("empty_db"), clean_env / "mlflow.db")
    before = (clean_env / "mlflow.db").read_bytes()
    check_tracking_first(cli.parse_command(["registry", "list"]), commands.find(["registry", "list"]))
    assert (clean_env / "mlflow.db").read_bytes() == before


# ---- a server URI with credentials (issue 32, item 17) -------------------------------------------------------------
class _AuthRecorder:
    """A tracking server on 127.0.0.1 that answers every request and records its Authorization header."""

    def __enter__(self):
        import http.server
        import threading

        seen = self.seen = []

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):                        # noqa: N802 — http.server's name
                seen.append((self.path, self.headers.get("Authorization")))
                self.send_response(200)
                self.end_headers()

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.port = self.server.server_address[1]
        return self

    def __exit__(self, *exc):
        self.server.shutdown()
        self.server.server_close()


def test_a_server_uri_with_credentials_is_reached_and_sends_them_as_basic_auth():
    """Before: urllib looked up "alice:s3cr%40t@127.0.0.1" as a host name ("Name or service not known") while the
    server listened. MLflow 3 sends a URI's user:password as basic auth (requests takes them from the URL): so does
    the check, on the host without them."""
    import base64

    from bodyschema.training.registry import check_tracking

    with _AuthRecorder() as server:
        check_tracking(f"http://alice:s3cr%40t@127.0.0.1:{server.port}", timeout_s=5)
    assert server.seen == [("/health", "Basic " + base64.b64encode(b"alice:s3cr@t").decode())]


def test_an_unreachable_server_uri_never_shows_its_password(clean_env, capsys):
    import socket

    with socket.socket() as probe:                   # a free loopback port: nothing listens there
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    for uri in (f"http://alice:s3cret@127.0.0.1:{port}", "htp://alice:s3cret@127.0.0.1:9"):
        assert cli.main(["registry", "list", "--tracking-uri", uri]) == 2
        err = capsys.readouterr().err
        assert "s3cret" not in err and "alice:***@127.0.0.1" in err and " must be " in err, err
