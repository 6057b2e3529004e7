"""The CLI's error boundary: what is an expected failure (house line, exit 2) and what is a bug (traceback, exit 1),
--debug, Ctrl-C, the tracking check before MLflow work, and the rendering default set before mujoco is imported."""

from __future__ import annotations

import os
import pickle
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bodyschema.cli as cli
from bodyschema.errors import explain, must_be


# ---- explain: the one mapping from exception to house line ---------------------------------------------------
def test_a_house_message_passes_through_unchanged():
    message = must_be("n", "an integer >= 1", 0)
    assert explain(ValueError(message)) == message
    assert explain(TypeError(message)) == message                 # a TypeError raised on purpose is expected too


def test_a_typeerror_from_our_own_code_is_a_bug():
    def buggy():
        return 1 < "a"

    with pytest.raises(TypeError) as caught:
        buggy()
    assert explain(caught.value) is None
    assert explain(AssertionError("x")) is None and explain(NameError("x")) is None


def test_a_crafted_pickle_is_refused_and_the_message_does_not_advise_weights_only_false(tmp_path):
    import torch

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {tmp_path / 'PWNED'}",))

    (tmp_path / "state.pt").write_bytes(pickle.dumps(Payload()))
    with pytest.raises(pickle.UnpicklingError) as caught:
        torch.load(tmp_path / "state.pt", weights_only=True)
    line = explain(caught.value)
    assert line.startswith("a saved model's state.pt must be tensors only")
    assert "weights_only` set to `False`" not in line and "weights_only=False" not in line
    assert not (tmp_path / "PWNED").exists()


def test_a_truncated_zarr_chunk_is_a_file_error_not_a_bug(tmp_path):
    import zarr

    array = zarr.create_array(tmp_path / "a.zarr", shape=(64, 64), chunks=(64, 64), dtype="uint8")
    array[:] = np.arange(64 * 64).reshape(64, 64) % 251
    chunk = next(p for p in (tmp_path / "a.zarr").rglob("*") if p.is_file() and p.name != "zarr.json")
    chunk.write_bytes(chunk.read_bytes()[: chunk.stat().st_size // 2])
    with pytest.raises(Exception) as caught:
        zarr.open_array(tmp_path / "a.zarr", mode="r")[:]
    line = explain(caught.value)
    assert line is not None and " must be complete and well-formed" in line, line


@pytest.mark.parametrize("error, start", [
    (FloatingPointError("validation loss is nan"), "the computation must be finite"),
    (FileNotFoundError(2, "No such file or directory", "/no/such"), "/no/such must be an existing file"),
    (PermissionError(13, "Permission denied", "/root/x"), "/root/x must be readable and writable"),
    (ConnectionRefusedError(111, "Connection refused"), "the connection must be answered"),
    (MemoryError(), "the memory this run needs must be available"),
])
def test_environment_and_numerical_failures_read_as_house_lines(error, start):
    assert explain(error).startswith(start)


def test_library_failures_read_as_house_lines():
    import mujoco
    from mlflow.exceptions import MlflowException

    assert explain(mujoco.FatalError("gladLoadGL error")).startswith("MuJoCo rendering must be available")
    assert "MUJOCO_GL=egl" in explain(mujoco.FatalError("gladLoadGL error"))
    assert explain(MlflowException("RESOURCE_DOES_NOT_EXIST: x")).startswith(
        "the MLflow request must be accepted by the tracking store")


# ---- main: exit codes, --debug, Ctrl-C ------------------------------------------------------------------
ARGV = ["report", "--results", "."]                   # any valid command; `run` is replaced below


@pytest.mark.parametrize("raised, code", [(ValueError(must_be("x", "1", 2)), 2), (FloatingPointError("nan"), 2),
                                          (AssertionError("bug"), 1), (NameError("bug"), 1),
                                          (TypeError("unsupported operand"), 1)])
def test_expected_failures_exit_2_without_traceback_and_bugs_exit_1_with_one(raised, code, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run", lambda *args: (_ for _ in ()).throw(raised))
    monkeypatch.delenv("BODYSCHEMA_DEBUG", raising=False)
    assert cli.main(ARGV) == code
    err = capsys.readouterr().err
    assert err.rstrip().splitlines()[-1].startswith("bodyschema report: ")
    assert ("Traceback" in err) == (code == 1)


@pytest.mark.parametrize("how", ["flag", "env"])
def test_debug_shows_the_traceback_of_an_expected_failure(how, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run", lambda *args: (_ for _ in ()).throw(ValueError(must_be("x", "1", 2))))
    monkeypatch.setenv("BODYSCHEMA_DEBUG", "1" if how == "env" else "0")
    assert cli.main(["--debug", *ARGV] if how == "flag" else ARGV) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and err.rstrip().endswith("x must be 1. Got 2.")


def test_ctrl_c_exits_130_with_one_line(monkeypatch, capsys):
    monkeypatch.setattr(cli, "run", lambda *args: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert cli.main(ARGV) == 130
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "interrupted" in err and "Traceback" not in err


# ---- the tracking check ---------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, uses", [
    (["train", "gpr", "--data", "d.zarr"], True),
    (["registry", "list"], True),
    (["evaluate", "levels"], True),
    (["evaluate", "levels", "--no-mlflow"], False),
    (["evaluate", "levels", "--no-mlflow", "--model", "models:/bodyschema-x@champion"], True),
    (["evaluate", "robustness"], True),
    (["evaluate", "loop-robustness", "--no-mlflow"], False),
    (["datagen"], False),
    (["report"], False),
    (["demo"], True),
])
def test_every_command_that_talks_to_mlflow_is_checked_first(argv, uses):
    from bodyschema import commands
    from bodyschema.tracking_check import tracking_of

    assert tracking_of(cli.parse_command(argv), commands.find(commands.words_of(argv)).mlflow)[0] is uses


def test_the_tracking_uri_is_named_and_a_silent_server_fails_within_the_timeout(monkeypatch, capsys):
    server = socket.socket()                             # accepts connections, never answers
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    uri = f"http://127.0.0.1:{server.getsockname()[1]}"
    import bodyschema.training.registry as registry

    real = registry.check_tracking
    monkeypatch.setattr(registry, "check_tracking", lambda u, timeout_s=5: real(u, timeout_s=0.5))
    try:
        assert cli.main(["registry", "list", "--tracking-uri", uri]) == 2
    finally:
        server.close()
    err = capsys.readouterr().err
    assert f"tracking: {uri}" in err and "tracking server must be answering" in err and "Traceback" not in err


# ---- rendering default ------------------------------------------------------------------------------------
def test_datagen_renders_without_mujoco_gl_in_the_environment(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    script = shutil.which("bodyschema", path=str(Path(sys.executable).parent))
    command = [script] if script else [sys.executable, "-m", "bodyschema.cli"]
    out = tmp_path / "p.zarr"
    result = subprocess.run([*command, "datagen", "--robot", "planar2", "--n", "16", "--out", str(out)],
                            env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    import zarr

    images = zarr.open_group(out, mode="r")["image"][:]                  # (16, H, W) uint8
    assert images.shape[0] == 16 and images.std() > 0, "no image rendered"
    assert all(frame.std() > 0 for frame in images), "a blank frame"
    assert not any(np.array_equal(images[0], frame) for frame in images[1:]), "poses differ, so must the frames"
