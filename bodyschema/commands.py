"""The CLI as a table: one `Command` per leaf command (its words, help, config class, runner, and whether it talks to
MLflow), and the tyro type built from it (`tyro_type`).

A group (`train`, `evaluate adaptation`) is the words its commands share, in the place of its first command; its
help is in GROUPS. The train kinds come from the model registry (models/kinds.py), the benchmarks from
evaluation/registry.py, so the table is built on each call (`table()`).

Start-up stays fast (bench/startup.py): only light config modules are imported here; a benchmark's config is
imported only when the command line names it (`tyro_type(words)`), another stands in as an empty placeholder that
carries its name and help.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Union

import tyro

from bodyschema import export_commands as export
from bodyschema.command_configs import RegistryList, RegistryPromote, ValidateArgs
from bodyschema.datagen.body import commands as robot
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.demo_config import DemoConfig
from bodyschema.evaluation import registry
from bodyschema.evaluation.report import ReportConfig
from bodyschema.reproduce.config import ReproduceConfig
from bodyschema.training.config import train_commands
from bodyschema.training.sweep_config import SweepConfig


@dataclass(frozen=True)
class Command:
    words: tuple[str, ...]                  # `bodyschema <words>`
    help: str                               # one line, in the help of the group above it
    config: Callable[[], type]              # its config class; a call, so a benchmark's package loads only if named
    run: Callable[..., int | None]          # config → exit code (None: 0)
    mlflow: bool = False                    # always talks to MLflow (else only if its config asks or names models:/)
    reads_models: bool = False              # reads models from the store: a store that does not exist is a typo
    lazy: bool = False                      # its config is heavy to import: a placeholder unless named


GROUPS = {
    ("robot",): "A robot from a model file: write its record, look at it.",
    ("train",): "Fit one sensory model on a dataset, log it to MLflow and register it. "
                "`bodyschema train KIND --help` lists KIND's hyper-parameters with their defaults.",
    ("registry",): "Inspect and manage the MLflow model registry.",
    ("export",): "Export a dataset (HDF5, LeRobot) or a model (ONNX) for other tools.",
    ("evaluate",): "Run an evaluation benchmark; each run writes results/<name>/<run-id>/ and links latest.",
    **{("evaluate", word): help for word, help in registry.GROUPS.items()},
}


def _is(cls: type) -> Callable[[], type]:
    return lambda: cls


def table() -> list[Command]:
    """Every command, in the order of the help."""
    return [
        Command(("datagen",), "Generate a motor-babbling dataset (Zarr v3).", _is(DatagenConfig),
                _in_runners("run_datagen")),
        Command(("validate",), "Check a dataset store; exit 0 when valid, else list every problem.",
                _is(ValidateArgs), _in_runners("run_validate")),
        Command(("show",), "Summarize a dataset store and draw a contact sheet of its images (PNG).",
                _is(export.ShowArgs), export.run_show),
        Command(("robot", "init"), "Write the robot record of an MJCF/URDF file with inferred values, to edit.",
                _is(robot.RobotInitArgs), robot.run_init),
        Command(("robot", "show"), "A robot's joints, sites, cameras, record and view of its ee, and a sheet.",
                _is(robot.RobotShowArgs), robot.run_show),
        Command(("robot", "camera"), "Place a record's camera anew for its (edited) workspace.",
                _is(robot.RobotCameraArgs), robot.run_camera),
        Command(("import",), "Import recordings (images + CSV of angles, HDF5, LeRobot v3.0) into a dataset store.",
                _is(ImportConfig), _in_runners("run_import")),
        *(Command(("train", kind), help, _is(config), _in_runners("run_train"), mlflow=True)
          for kind, config, help in train_commands()),
        Command(("sweep",), "Grid or random search over a kind's hyper-parameters on Ray Tune: one MLflow parent run, "
                "a child per trial, the best registered (champion if better).", _is(SweepConfig),
                _in_runners("run_sweep"), mlflow=True),
        Command(("registry", "list"), "List registered model versions, metrics and aliases.",
                _is(RegistryList), _in_runners("run_registry_list"), mlflow=True, reads_models=True),
        Command(("registry", "promote"), "Move the `champion` alias to NAME's VERSION.", _is(RegistryPromote),
                _in_runners("run_registry_promote"), mlflow=True, reads_models=True),
        Command(("export", "dataset"), "A dataset store as HDF5 or in LeRobot's v3.0 layout.",
                _is(export.ExportDatasetArgs), export.run_export_dataset),
        Command(("export", "onnx"), "A fitted model as ONNX: rad in, prediction out, checked with onnxruntime.",
                _is(export.ExportOnnxArgs), export.run_export_onnx),
        *(Command(("evaluate", *b.words), b.help, lambda b=b: b.config, printing_paths(lambda b=b: b.run),
                  lazy=True) for b in registry.BENCHMARKS),
        Command(("report",), "Gather the latest run of every benchmark on each robot into results/report.md and "
                ".html, key figures first.", _is(ReportConfig), printing_paths(_report)),
        Command(("demo",), "The end-to-end demo: babble, fit, register, perceive, reach, recognise, report.",
                _is(DemoConfig), _in_runners("run_demo"), mlflow=True),
        Command(("reproduce",), "Regenerate the README's measured tables with its own commands, each beside the "
                "README's figures; resumable (hours on 2 cores).", _is(ReproduceConfig), _in_runners("run_reproduce")),
    ]


def printing_paths(runner: Callable[[], Callable]) -> Callable:
    """A benchmark's or the report's runner (`runner()` imports it) that prints the paths it wrote."""
    def run(config) -> None:
        written = runner()(config)
        paths = getattr(written, "paths", written)                         # levels: a summary holding its paths
        print("\n".join(f"{k}: {v}" for k, v in paths.items()))
    return run


def _in_runners(name: str) -> Callable:
    """The runner `name` of bodyschema/runners.py, imported when the command runs: the table names its runners
    instead of importing them, because a runner (reproduce) parses command lines with this table (parsing.py)."""
    def run(config):
        return getattr(importlib.import_module("bodyschema.runners"), name)(config)
    return run


def _report():
    from bodyschema.evaluation.report import write_report
    return write_report


def find(words: list[str] | tuple[str, ...]) -> Command | None:
    """The command `bodyschema <words>` names (None: a group, or no command)."""
    return next((c for c in table() if c.words == tuple(words)), None)


def words_of(argv: list[str]) -> list[str]:
    """The command words at the start of `argv` (a group's or a command's): each continues a command's words, so a
    command's own positional argument is not one (`sweep mdn`: mdn is the kind, not `train mdn`)."""
    paths = [c.words for c in table()]
    words: list[str] = []
    for arg in argv:
        if (*words, arg) not in {p[:len(words) + 1] for p in paths}:
            break
        words.append(arg)
    return words


def tyro_type(words: list[str] | None = None):
    """The tyro type of the whole CLI. `words`: the command words given (`words_of`); a lazy command's config is
    imported only when they name it. None: every command's real config (tests)."""
    return _union(table(), (), words)


def _union(commands: list[Command], prefix: tuple[str, ...], named: list[str] | None):
    """The subcommands below `prefix`: a command, or a group at its first command's place."""
    members, seen = [], set()
    for command in commands:
        word = command.words[len(prefix)]
        if word in seen:
            continue
        seen.add(word)
        if len(command.words) == len(prefix) + 1:
            members.append(_subcommand(word, _config_of(command, named), command.help))
        else:
            below = [c for c in commands if c.words[len(prefix)] == word]
            members.append(_subcommand(word, _union(below, (*prefix, word), named), GROUPS[(*prefix, word)]))
    return Union[tuple(members)]  # noqa: UP007 — tyro reads subcommands from typing.Union


def _subcommand(name: str, kind, description: str):
    return Annotated[kind, tyro.conf.subcommand(name, description=description)]


def _config_of(command: Command, named: list[str] | None) -> type:
    if not command.lazy or named is None or tuple(named[:len(command.words)]) == command.words:
        return command.config()
    return _placeholder(command)


def _placeholder(command: Command) -> type:
    """An empty stand-in for a command the command line does not name: the `--help` of the groups above it shows
    only its name and help, and its real config would import its package (torch, MuJoCo) for nothing."""
    cls = dataclasses.make_dataclass("Benchmark_" + "_".join(command.words[1:]).replace("-", "_"), [], frozen=True)
    cls.__doc__ = command.help
    return cls
