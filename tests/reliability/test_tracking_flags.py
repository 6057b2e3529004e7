"""Bad input to `bodyschema evaluate tracking` (issue 32, item 13, and its --help): Π = 0 ignores a modality, as in
every benchmark, so a sensing condition left without one is the house error (it was a ZeroDivisionError); --rates is
bounded and distinct; `--help | head` neither touches the tracking store nor prints a broken-pipe error."""

from __future__ import annotations

import http.server
import os
import subprocess
import sys
import threading

import pytest

from bodyschema.evaluation.tracking.benchmark import MAX_RATES, TrackingConfig, check_informed
from tests.test_cli_fuzz import run_and_check

TRACKING = "evaluate tracking --trials 1 --duration 0.2 --no-mlflow --out {W}/res "
CASES = [
    ("tracking-precision-0-only-modality", TRACKING + "--precisions ee_xyz 0 --rates 10"),
    ("tracking-precision-0-unfused", TRACKING + "--precisions ee_xyz 0 --fuse-joints False True --rates 10"),
    ("tracking-rates-200", TRACKING + "--rates " + " ".join(str(k) for k in range(1, 201))),
    ("tracking-rates-repeated", TRACKING + "--rates 10 10"),
    ("tracking-precision-negative", TRACKING + "--precisions ee_xyz -1 --rates 10"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("tracking_flags"))


def make_world(w):
    return w                                         # the default model is analytic: nothing to prepare


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_tracking_flags_are_a_clear_error(case_id, command, in_world, capsys):
    err = run_and_check(case_id, command, in_world, capsys)
    assert not (in_world / "res").exists(), "no run folder"
    if "precision-0" in case_id:
        assert "precisions must be > 0 for one modality of each sensing condition (ee_xyz" in err, err


def test_a_zero_precision_with_another_modality_runs_and_ignores_it():
    """Π = 0 on ee_xyz with the joint encoders fused: the condition keeps the joints, so it is accepted."""
    from bodyschema.evaluation.core.specs import resolve_models

    models = resolve_models(("analytic:planar2:ee_xyz",), (), None)
    check_informed(TrackingConfig(precisions=(("ee_xyz", 0.0),), fuse_joints=(True,)), models)
    with pytest.raises(ValueError, match="precisions must be > 0"):
        check_informed(TrackingConfig(precisions=(("ee_xyz", 0.0),), fuse_joints=(True, False)), models)


def test_rates_up_to_the_bound_are_accepted():
    TrackingConfig(rates=tuple(float(k) for k in range(1, MAX_RATES + 1)), duration=1.0)
    with pytest.raises(ValueError, match=f"at most {MAX_RATES} distinct frame rates"):
        TrackingConfig(rates=tuple(float(k) for k in range(1, MAX_RATES + 2)), duration=1.0)


class _Recorder(http.server.BaseHTTPRequestHandler):
    hits: list[str] = []

    def do_GET(self):                                # noqa: N802 — http.server's name
        self.hits.append(self.path)
        self.send_response(200)
        self.end_headers()

    do_POST = do_GET

    def log_message(self, *args):
        pass


def test_help_piped_to_head_is_quiet_and_touches_no_tracking_store(tmp_path):
    """Before: `evaluate tracking --help | head` said "the connection must be answered. Got '[Errno 32] Broken
    pipe'" and exited 2. The help text is longer than a pipe's buffer: the reader leaves after one line."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Recorder)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        env = {**os.environ, "MLFLOW_TRACKING_URI": f"http://127.0.0.1:{server.server_address[1]}"}
        env.pop("BODYSCHEMA_DEBUG", None)
        read, write = os.pipe()
        os.close(read)                               # `| head` gone before the help is written: every write fails
        cli = subprocess.run([sys.executable, "-m", "bodyschema.cli", "evaluate", "tracking", "--help"],
                             cwd=tmp_path, env=env, stdout=write, stderr=subprocess.PIPE, text=True, timeout=60)
        os.close(write)
    finally:
        server.shutdown()
    assert cli.stderr == "", cli.stderr
    assert cli.returncode == 141, cli.returncode    # the status of a process SIGPIPE ends, as `seq 1 1e6 | head`
    assert _Recorder.hits == [], "--help contacted the tracking server"
    assert os.listdir(tmp_path) == [], "--help wrote a file"
