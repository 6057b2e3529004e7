"""--quiet/--verbose: one `bodyschema` logger, flags before or after the subcommand, debug lines only with --verbose,
progress bars on in the CLI (off with --quiet) and off in library calls, bars in a log file redrawn rarely, MLflow's
own chatter silenced unless --verbose (in library calls too), the tracking URI named even with --quiet and without
its password; config errors without tyro's internal names."""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass

import pytest
import torch

from bodyschema import cli, log
from bodyschema.tracking_check import dataclass_tree
from tests.training.conftest import empty_db, kin_store, tiny_kind, workdir  # noqa: F401 — fixtures, by name


@pytest.fixture(autouse=True)
def restore_logging_and_env():
    """configure() sets environment defaults and the logger's level: undo both for the next test."""
    env = dict(os.environ)
    yield
    os.environ.clear()
    os.environ.update(env)
    logging.getLogger(log.LOGGER).setLevel(logging.NOTSET)
    log._verbosity = None                                           # a library call again


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
    last = capsys.readouterr().err.splitlines()[-1]                  # --verbose: debug lines before it
    assert last.startswith("bodyschema validate: error: path must be an existing .zarr store")


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


@pytest.mark.parametrize("verbosity, on", [(None, False), (log.QUIET, False), (log.NORMAL, True), (log.VERBOSE, True)])
def test_every_progress_flag_of_the_tree_is_the_clis_and_off_in_a_library_call(verbosity, on, monkeypatch):
    train = cli.parse_command(["train", "gpr", "--data", "d.zarr"])
    monkeypatch.setattr(log, "_verbosity", verbosity)
    assert log.progress_bars() is on
    assert log.progress_of(Outer()) == Outer(inner=Inner(progress=on), progress=on, n=3)
    assert log.progress_of(train).progress is on and log.progress_of(train).model == train.model


@pytest.mark.parametrize("argv, on", [(["evaluate", "levels"], True), (["evaluate", "levels", "--no-progress"], False),
                                      (["evaluate", "loop-robustness", "--no-progress"], False)])
def test_the_cli_shows_bars_unless_told_not_to(argv, on, monkeypatch):
    monkeypatch.setattr(log, "_verbosity", log.NORMAL)
    config = log.progress_of(cli.parse_command(argv), cli.progress_flag(argv))
    assert all(c.progress is on for c in dataclass_tree(config) if hasattr(c, "progress"))


def test_a_benchmark_config_from_python_shows_no_bars():
    from bodyschema.evaluation.levels import LevelsConfig

    assert LevelsConfig().progress is False


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
        return subprocess.run([script, *flags, "registry", "list", "--tracking-uri", uri, "--create"],
                              capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)

    for db, flags in (("a.db", ()), ("b.db", ("--quiet",)), ("c.db", ("--verbose",))):
        done = run(db, *flags)
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "no registered bodyschema models"
        assert f"tracking: sqlite:///{tmp_path / db}" in done.stderr
        chatter = [line for line in done.stderr.splitlines() if " INFO mlflow" in line]
        assert bool(chatter) is (flags == ("--verbose",)), done.stderr


def test_the_tracking_line_stays_with_quiet_on_stderr_only(tmp_path, request, capsys):
    shutil.copy(request.getfixturevalue("empty_db"), tmp_path / "mlflow.db")     # an existing, empty store
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


def test_the_tracking_line_never_shows_a_password(capsys):
    assert log.masked("postgresql://me:s3cr:et@db.example:5432/mlflow") == "postgresql://me:***@db.example:5432/mlflow"
    assert log.masked("https://me:pw@host/x") == "https://me:***@host/x"
    assert log.masked("sqlite:////home/me/mlflow.db") == "sqlite:////home/me/mlflow.db"
    cli.main(["registry", "list", "--tracking-uri", "mysql://u:secret@127.0.0.1/db"])   # no driver, or no server
    err = capsys.readouterr().err
    assert "tracking: mysql://u:***@127.0.0.1/db" in err and "secret" not in err, err


# ---- --verbose: debug lines ----------------------------------------------------------------------------------
DEBUG_LINES = ("bodyschema datagen: DatagenConfig(", "datagen: 16 samples in 2 shards of 8 rows; backend loky",
               "bodyschema datagen: ")


@pytest.mark.parametrize("flags", [("--verbose",), ()])
def test_verbose_datagen_shows_its_config_shards_backend_and_seconds(flags, tmp_path, capsys):
    out = tmp_path / "p.zarr"
    argv = [*flags, "datagen", "--robot", "planar2", "--n", "16", "--shard-size", "8", "--workers", "1", "--out",
            str(out)]
    assert cli.main(argv) == 0
    err = capsys.readouterr().err.splitlines()
    shown = [line for line in err if line.startswith(DEBUG_LINES)]
    if flags:
        assert len(shown) == 3 and shown[-1].endswith(" s"), err    # config, plan, the command's seconds
    else:
        assert not shown, err


@pytest.mark.usefixtures("workdir", "tiny_kind")     # a fresh store in the cwd; the fast "tiny" model kind
@pytest.mark.parametrize("flags", [("--verbose",), ()])
def test_verbose_train_times_its_steps_and_names_the_registry_steps(flags, request, capsys):
    store = request.getfixturevalue("kin_store")
    assert cli.main([*flags, "train", "tiny", "--data", str(store), "--epochs", "3", "--no-progress"]) == 0
    err = capsys.readouterr().err
    steps = ("data read from", "split by", "epoch 2 at", "fit (tiny on", "ee_xyz: scored and plotted",
             "metrics and plots logged", "ee_xyz: model logged and registered",
             "registered bodyschema-planar2-ee_xyz-tiny v1")
    for step in steps:
        assert (step in err) is bool(flags), (step, err)


# ---- a library call prints nothing unless asked -----------------------------------------------------------
@pytest.fixture
def as_a_library(monkeypatch):
    """The state of a script that imported bodyschema: no configure(), MLflow's loggers at MLflow's own INFO, none of
    the environment switches the CLI sets."""
    monkeypatch.setattr(log, "_verbosity", None)
    for name in (*log.MLFLOW_QUIET_ENV, "TQDM_DISABLE", "TQDM_MININTERVAL"):
        monkeypatch.delenv(name, raising=False)
    for name in log.MLFLOW_LOGGERS:
        monkeypatch.setattr(logging.getLogger(name), "level", logging.INFO)


@pytest.mark.usefixtures("as_a_library", "workdir", "tiny_kind")
def test_train_called_from_python_prints_nothing(request, capfd):
    """A fresh store (MLflow's "Creating initial MLflow database tables..."), a fit, a registered version."""
    from bodyschema.training.train import train
    from tests.training.tiny_model import tiny_config

    os.remove("mlflow.db")                                          # workdir's copy: MLflow creates its tables
    result = train(tiny_config(request.getfixturevalue("kin_store"), epochs=3))
    assert result.model_version == "1"
    assert capfd.readouterr() == ("", "")


@pytest.mark.usefixtures("as_a_library")
def test_a_network_fit_called_from_python_prints_nothing_by_default_and_a_bar_when_asked(capfd):
    from bodyschema.models import _nn_fit

    module, data = torch.nn.Linear(2, 3), (torch.randn(32, 2), torch.randn(32, 3))
    settings = _nn_fit.TrainSettings(epochs=3, batch_size=8, lr=1e-2, patience=3, weight_decay=0.0)

    def loss(m, q, x):
        return (m(q) - x).pow(2).mean()

    _nn_fit.train(module, loss, data, settings, torch.Generator().manual_seed(0), desc="quiet fit")
    assert capfd.readouterr() == ("", "")
    _nn_fit.train(module, loss, data, settings, torch.Generator().manual_seed(0), desc="asked", progress=True)
    assert "asked" in capfd.readouterr().err


@pytest.mark.usefixtures("as_a_library")
def test_a_model_fit_called_from_python_prints_nothing(capfd):
    from bodyschema.models import MDNModel
    from tests.toy_models import ToyPlanarArm

    q = torch.rand(64, 2, dtype=torch.float64)
    MDNModel(ToyPlanarArm().body, "ee_xyz", (3,), epochs=2).fit(q, ToyPlanarArm().predict(q))
    assert capfd.readouterr() == ("", "")


@pytest.mark.usefixtures("as_a_library", "workdir", "tiny_kind")
def test_load_registered_prints_nothing(request, capfd):
    import bodyschema
    from bodyschema.training.train import train
    from tests.training.tiny_model import tiny_config

    name = train(tiny_config(request.getfixturevalue("kin_store"), epochs=2)).registered_name
    capfd.readouterr()
    assert bodyschema.load_registered(f"models:/{name}@champion").is_fitted
    assert capfd.readouterr() == ("", "")


# ---- bars: long phases have one, a log file gets few redraws ----------------------------------------------
def test_image_goal_imagination_counts_its_starts_and_finds_what_one_batch_finds(capfd):
    from bodyschema.aif.goal_inference import infer_goal_pose
    from bodyschema.aif.perception import Perception, PerceptionConfig
    from tests.aif.toys import ToyBlobImage, planar_poses

    image = ToyBlobImage()
    perception = Perception([image], PerceptionConfig(max_steps=15))        # the same search, not run to the end
    goal = {"image": image.predict(planar_poses(3, seed=5))}
    belief, guesses = torch.zeros(3, 2), planar_poses(6, seed=6).reshape(3, 2, 2)
    quiet = infer_goal_pose(perception, goal, belief, guesses)
    assert capfd.readouterr() == ("", ""), "no bar unless asked"
    shown = infer_goal_pose(perception, goal, belief, guesses, progress=True)
    err = capfd.readouterr().err
    # "/3": a bar over the 3 starts; its last redraw (3/3) depends on the clock in a log file (30 s), so not asserted
    assert "imagining 3 goals" in err and "/3" in err and "start" in err, err
    assert torch.equal(shown.q, quiet.q)
    starts = torch.cat([belief[:, None].double(), guesses], dim=1).reshape(9, 2)
    batch = perception.infer({"image": goal["image"].repeat_interleave(3, dim=0)}, starts)     # every start at once
    rows = torch.arange(3) * 3 + quiet.chosen
    assert torch.allclose(quiet.q, batch.mu[rows], atol=1e-6), "the same search, a start at a time"


def test_other_goals_are_imagined_in_one_batch_under_a_timer_bar_when_asked(capfd):
    from bodyschema.aif.goal_inference import infer_goal_pose
    from bodyschema.aif.perception import Perception
    from tests.aif.toys import planar_poses
    from tests.toy_models import ToyPlanarArm

    arm = ToyPlanarArm()
    perception, goal = Perception([arm]), {"ee_xyz": arm.predict(planar_poses(5, seed=1))}
    guesses = planar_poses(10, seed=2).reshape(5, 2, 2)
    quiet = infer_goal_pose(perception, goal, torch.zeros(5, 2), guesses)
    assert capfd.readouterr() == ("", ""), "no bar unless asked"
    shown = infer_goal_pose(perception, goal, torch.zeros(5, 2), guesses, progress=True)
    assert "imagining 5 goals from 3 starts: 00:0" in capfd.readouterr().err
    assert torch.equal(shown.q, quiet.q)


def test_a_bar_written_to_a_file_redraws_rarely(tmp_path):
    """configure() with stderr not a terminal: tqdm's redraws at most every FILE_BAR_INTERVAL_S (a 1 s loop of 100
    updates redraws twice: its start and its end), in any bar of the process, not only ours."""
    code = ("import time, sys\nfrom bodyschema import log\nlog.configure()\nfrom tqdm.auto import tqdm\n"
            "for _ in tqdm(range(100), desc='phase'):\n    time.sleep(0.01)\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("TQDM_")}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("phase") <= 2 and "100/100" in done.stderr, done.stderr
