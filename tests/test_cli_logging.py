"""--quiet/--verbose: one `bodyschema` logger, flags before or after the subcommand, progress bars off with --quiet,
MLflow's own chatter silenced unless --verbose, the tracking URI named even with --quiet; config errors without
tyro's internal names."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from dataclasses import dataclass

import pytest
import tyro

from bodyschema import cli, log


@pytest.fixture(autouse=True)
def restore_logging_and_env():
    """configure() sets environment defaults and the logger's level: undo both for the next test."""
    env = dict(os.environ)
    yield
    os.environ.clear()
    os.environ.update(env)
    logging.getLogger(log.LOGGER).setLevel(logging.NOTSET)
    log._verbosity = log.NORMAL


@pytest.mark.parametrize("argv, verbosity", [
    (["--quiet", "validate", "x.zarr"], log.QUIET), (["validate", "x.zarr", "--quiet"], log.QUIET),
    (["-v", "validate", "x.zarr"], log.VERBOSE), (["validate", "--verbose", "x.zarr"], log.VERBOSE),
    (["validate", "x.zarr"], log.NORMAL)])
def test_the_flags_are_global_before_or_after_the_subcommand(argv, verbosity):
    assert log.split_flags(argv) == (verbosity, ["validate", "x.zarr"])


@pytest.mark.parametrize("flag", ["--quiet", "--verbose"])
def test_a_command_with_either_flag_runs_and_names_itself_in_errors(flag, tmp_path, capsys):
    missing = tmp_path / "none.zarr"
    assert cli.main([flag, "validate", str(missing)]) == 2
    assert capsys.readouterr().err.startswith("bodyschema validate: error: path must be an existing .zarr store")


def test_quiet_and_verbose_together_are_refused(capsys):
    assert cli.main(["validate", "x.zarr", "-q", "--verbose"]) == 2
    err = capsys.readouterr().err
    assert "bodyschema validate: error: --quiet and --verbose must be given one at a time" in err


@pytest.mark.parametrize("verbosity, shown", [(log.QUIET, {"warning"}), (log.NORMAL, {"warning", "info"}),
                                              (log.VERBOSE, {"warning", "info", "debug"})])
def test_a_stage_logger_prints_by_verbosity_on_stderr_only(verbosity, shown, capsys):
    log.configure(verbosity)
    stage = logging.getLogger("bodyschema.datagen.generate")        # any module's logger is a child
    stage.debug("debug")
    stage.info("info")
    stage.warning("warning")
    out, err = capsys.readouterr()
    assert out == "" and set(err.split()) == shown


def test_configure_twice_prints_each_line_once(capsys):
    log.configure(log.NORMAL)
    log.configure(log.NORMAL)
    logging.getLogger("bodyschema.x").info("once")
    assert capsys.readouterr().err.split() == ["once"]


def test_mlflow_is_silenced_unless_verbose_and_a_value_the_user_set_wins(monkeypatch):
    monkeypatch.delenv("MLFLOW_LOGGING_LEVEL", raising=False)
    monkeypatch.setenv("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "true")          # the user's choice
    log.configure(log.NORMAL)
    assert os.environ["MLFLOW_LOGGING_LEVEL"] == "WARNING"
    assert os.environ["MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR"] == "true"
    assert logging.getLogger("mlflow.store.db.utils").getEffectiveLevel() == logging.WARNING


@dataclass(frozen=True)
class Inner:
    progress: bool = True


@dataclass(frozen=True)
class Outer:
    inner: Inner = Inner()
    progress: bool = True
    n: int = 3


def test_quiet_turns_every_progress_flag_of_the_tree_off(monkeypatch):
    train = tyro.cli(cli.COMMANDS, args=["train", "gpr", "--data", "d.zarr"])
    assert log.progress_of(Outer()) == Outer(), "only under --quiet"
    monkeypatch.setattr(log, "_verbosity", log.QUIET)
    quiet, quiet_train = log.progress_of(Outer()), log.progress_of(train)
    assert quiet == Outer(inner=Inner(progress=False), progress=False, n=3)
    assert train.progress is True and quiet_train.progress is False
    assert quiet_train.model == train.model, "nothing else changes"


@pytest.mark.parametrize("argv, line", [
    (["train", "gpr", "--data", "d.zarr", "--noise-floor", "-1"],
     "bodyschema train gpr: error: --noise-floor must be a finite number ≥ 0. Got -1.0."),
    (["evaluate", "adaptation", "jupiter", "--trials", "0"],
     "bodyschema evaluate adaptation jupiter: error: trials must be at least 1. Got 0."),
])
def test_a_config_error_in_a_nested_subcommand_is_one_house_line_without_tyro_names(argv, line, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.strip() == line and "tyro" not in err


def test_tyro_names_are_stripped_from_any_error_line():
    raw = "Error parsing __tyro-dummy-inner__.__tyro-dummy-inner__.model: --noise-floor must be ≥ 0."
    assert cli.strip_tyro_names(raw) == "Error parsing model: --noise-floor must be ≥ 0."
    assert cli.strip_tyro_names("__tyro_dummy_inner__.trials must be at least 1.") == "trials must be at least 1."


@pytest.mark.slow
def test_registry_list_names_its_store_and_mlflow_speaks_only_when_verbose(tmp_path):
    """A fresh sqlite store makes MLflow log INFO lines (creating its tables): hidden by default and with --quiet,
    shown with --verbose; the tracking line is on stderr every time, the command's output on stdout."""
    script = os.path.join(os.path.dirname(sys.executable), "bodyschema")

    def run(db: str, *flags: str) -> subprocess.CompletedProcess:
        uri = f"sqlite:///{tmp_path / db}"
        env = {k: v for k, v in os.environ.items() if not k.startswith("MLFLOW_")}
        return subprocess.run([script, *flags, "registry", "list", "--tracking-uri", uri], capture_output=True,
                              text=True, cwd=tmp_path, env=env, timeout=600)

    for db, flags in (("a.db", ()), ("b.db", ("--quiet",)), ("c.db", ("--verbose",))):
        done = run(db, *flags)
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "no registered bodyschema models"
        assert f"tracking: sqlite:///{tmp_path / db}" in done.stderr
        chatter = [line for line in done.stderr.splitlines() if " INFO mlflow" in line]
        assert bool(chatter) is (flags == ("--verbose",)), done.stderr


def test_the_tracking_line_stays_with_quiet_on_stderr_only(tmp_path, capsys):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    assert cli.main(["--quiet", "registry", "list", "--tracking-uri", uri]) == 0
    out, err = capsys.readouterr()
    assert f"tracking: {uri}" in err.splitlines() and "tracking" not in out
    assert out.strip() == "no registered bodyschema models"


@pytest.mark.parametrize("flags, bar", [((), True), (("--quiet",), False)])
def test_quiet_hides_the_datagen_progress_bar_and_keeps_its_output(flags, bar, tmp_path, capsys):
    out = tmp_path / "p.zarr"
    assert cli.main([*flags, "datagen", "--robot", "planar2", "--n", "16", "--workers", "1", "--out", str(out)]) == 0
    stdout, stderr = capsys.readouterr()
    assert ("shard/s" in stderr) is bar, stderr
    assert "valid" in stdout, "the summary is the command's output, shown either way"
