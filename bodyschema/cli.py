"""`bodyschema <stage> ...`: one CLI over the pipeline's frozen dataclass configs (tyro).

    bodyschema datagen --robot nao_arm --n 2000 --sampler babble --workers 2 --out data/nao.zarr
    bodyschema validate data/nao.zarr
    bodyschema train --model gpr --data data/nao.zarr --modality ee_xyz
    bodyschema registry list | bodyschema registry promote NAME VERSION
    bodyschema evaluate levels --model models:/bodyschema-nao_arm-ee_xyz-gpr@champion --levels 1 2 3
    bodyschema evaluate reaching --robot nao_arm | evaluate adaptation jupiter | evaluate self-recognition
    bodyschema report
    bodyschema demo
    bodyschema --debug ...    (or BODYSCHEMA_DEBUG=1): show the traceback behind an error message

One error boundary (`main`): an expected failure (bad input, a bad file, MLflow, rendering, a non-finite
computation; the list is `bodyschema.errors.expected_types`) prints one house line on stderr and exits 2; a bug
prints its traceback and exits 1; Ctrl-C exits 130.
"""

from __future__ import annotations

import os

# Headless rendering by default. mujoco reads MUJOCO_GL once, when first imported, and the imports below reach
# it (evaluation.jupiter imports mujoco), so this must come first; a value the user set wins.
_GL = os.environ.setdefault("MUJOCO_GL", "egl")
if _GL in ("egl", "osmesa"):
    os.environ.setdefault("PYOPENGL_PLATFORM", _GL)
# (every import below comes after it on purpose)

import dataclasses
import inspect
import math
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Union

import tyro

from bodyschema.datagen.config import DatagenConfig
from bodyschema.demo import DemoConfig
from bodyschema.evaluation.jupiter import JupiterConfig, run_jupiter
from bodyschema.evaluation.levels import LevelsConfig, run_levels
from bodyschema.evaluation.loop_robustness import LoopRobustnessConfig, run_loop_robustness
from bodyschema.evaluation.marker_shift import MarkerShiftConfig, run_marker_shift
from bodyschema.evaluation.reaching import ReachingConfig, run_reaching
from bodyschema.evaluation.report import ReportConfig, write_report
from bodyschema.evaluation.robustness import RobustnessConfig, run_robustness
from bodyschema.evaluation.self_recognition import SelfRecognitionConfig, run_self_recognition
from bodyschema.errors import expected_types, explain, must_be
from bodyschema.training.config import TrainConfig


@dataclass(frozen=True)
class ValidateArgs:
    """Check a dataset store against the schema; exit 0 when valid, else list every problem."""

    path: tyro.conf.Positional[Path]  # the .zarr store


@dataclass(frozen=True)
class RegistryList:
    """List every registered bodyschema model version with its validation metric and aliases."""

    tracking_uri: str | None = None  # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db


@dataclass(frozen=True)
class RegistryPromote:
    """Move the `champion` alias to NAME's VERSION by hand."""

    name: tyro.conf.Positional[str]
    version: tyro.conf.Positional[int]
    tracking_uri: str | None = None


COMMAND_WORDS: set[str] = set()   # every subcommand name, to name the command in an error line


def _command(name: str, kind, description: str):
    COMMAND_WORDS.add(name)
    return Annotated[kind, tyro.conf.subcommand(name, description=description)]


def _group(name: str, description: str, *members):
    """members: (name, Config, description) triples, or groups built by _group."""
    built = tuple(_command(*m) if isinstance(m, tuple) else m for m in members)
    return _command(name, Union[built], description)  # noqa: UP007 (tyro: Union)


# Benchmarks and the report: Config → runner returning the paths it wrote (levels: a summary holding them).
BENCHMARKS = {LevelsConfig: run_levels, RobustnessConfig: run_robustness, ReachingConfig: run_reaching,
              LoopRobustnessConfig: run_loop_robustness, MarkerShiftConfig: run_marker_shift,
              JupiterConfig: run_jupiter, SelfRecognitionConfig: run_self_recognition, ReportConfig: write_report}


COMMANDS = Union[(  # noqa: UP007
    _command("datagen", DatagenConfig, "Generate a motor-babbling dataset (Zarr v3)."),
    _command("validate", ValidateArgs, "Check a dataset store; exit 0 when valid, else list every problem."),
    _command("train", TrainConfig, "Fit one sensory model on a dataset, log it to MLflow and register it."),
    _group("registry", "Inspect and manage the MLflow model registry.",
           ("list", RegistryList, "List registered model versions, metrics and aliases."),
           ("promote", RegistryPromote, "Move the `champion` alias to NAME's VERSION.")),
    _group("evaluate", "Run an evaluation benchmark.",
           ("levels", LevelsConfig, "Estimation levels 1–3: where is my body? (AIF perception)"),
           ("robustness", RobustnessConfig, "Joint error vs observation noise and with a broken sensor."),
           ("reaching", ReachingConfig, "Closed-loop AIF reaching to image / ee-pixel / ee-position goals vs PD."),
           ("loop-robustness", LoopRobustnessConfig, "Reaching success vs observation noise and with a sensor broken."),
           _group("adaptation", "Adaptation in the loop.",
                  ("marker-shift", MarkerShiftConfig, "(a) The visual marker moves on the hand at run time."),
                  ("jupiter", JupiterConfig, "(b) Gravity jumps to 24.79 m/s² mid-task: PD vs AIC on the panda.")),
           ("self-recognition", SelfRecognitionConfig, "Is this me? ROC/AUC of the free energy: own body vs others.")),
    _command("report", ReportConfig, "Gather every benchmark's tables and plots into results/report.md and .html."),
    _command("demo", DemoConfig, "The end-to-end demo: babble, fit, register, perceive, reach, recognise, report."),
)]


def run(config) -> int:
    """Run the stage a parsed config stands for; returns the process exit code."""
    if isinstance(config, TrainConfig):
        check_hyper(config)
    check_tracking_first(config)
    if isinstance(config, DatagenConfig):
        from bodyschema.datagen.generate import generate
        from bodyschema.datagen.validate import summarize_store

        print(summarize_store(generate(config)))
    elif isinstance(config, ValidateArgs):
        from bodyschema.datagen.validate import validate_store

        if not config.path.exists():     # bad input (exit 2), not an invalid store (exit 1)
            raise FileNotFoundError(must_be("path", "an existing .zarr store", str(config.path),
                                            "Create one with `bodyschema datagen --out PATH`."))
        problems = validate_store(config.path)
        for problem in problems:
            print(f"- {problem}", file=sys.stderr)
        print(f"{config.path}: {'valid' if not problems else f'{len(problems)} problem(s)'}")
        return 1 if problems else 0
    elif isinstance(config, TrainConfig):
        from bodyschema.training.train import train

        print(train(config))
    elif isinstance(config, RegistryList):
        from bodyschema.training.registry import list_models

        rows = list_models(tracking=config.tracking_uri)
        print("\n".join(map(str, rows)) if rows else "no registered bodyschema models")
    elif isinstance(config, RegistryPromote):
        from bodyschema.training.registry import promote

        promote(config.name, config.version, tracking=config.tracking_uri)
        print(f"{config.name} v{config.version} is now @champion")
    elif type(config) in BENCHMARKS:
        written = BENCHMARKS[type(config)](config)
        paths = getattr(written, "paths", written)                         # levels: a summary holding its paths
        print("\n".join(f"{k}: {v}" for k, v in paths.items()))
    elif isinstance(config, DemoConfig):
        from bodyschema.demo import run_demo

        run_demo(config)
    return 0


# ---- checks before any work ----------------------------------------------------------------------------
def check_hyper(config: TrainConfig) -> None:
    """Each --hyper value has the type of the model parameter it sets (a finite number where a number goes):
    otherwise a string such as "abc" or "nan" reaches the model and fails deep inside as a TypeError."""
    from bodyschema.training.config import model_class

    params = inspect.signature(model_class(config.model)).parameters
    problems = []
    for name, value in config.hyper_values().items():
        param = params.get(name)
        expected = _value_kind(param) if param is not None else None
        if expected is not None and not _is_kind(value, expected):
            problems.append(must_be(f"--hyper {name}", _KIND_TEXT[expected], config.hyper[name],
                                    f"{model_class(config.model).__name__}'s default is {param.default!r}."))
    if problems:
        raise ValueError("\n".join(problems))


_KIND_TEXT = {bool: "true or false", int: "an integer", float: "a finite number", tuple: "a list such as [64, 64]",
              str: "a word"}


def _value_kind(param: inspect.Parameter) -> type | None:
    """The kind of value a model parameter takes: from its default, else from its annotation (`int | None`)."""
    default = param.default
    for kind in (bool, int, float, tuple, str):                  # bool before int: True is an int
        if default is not inspect.Parameter.empty and default is not None and isinstance(default, kind):
            return kind
    text = str(param.annotation).removeprefix("typing.").split("|")[0].split("[")[0].strip()
    return {"bool": bool, "int": int, "float": float, "tuple": tuple, "str": str}.get(text)


def _is_kind(value, kind: type) -> bool:
    if value is None:
        return True                                               # JSON null: the model's own default
    if kind is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, kind)


def tracking_of(config) -> tuple[bool, str | None]:
    """(does this command talk to MLflow, its explicit tracking URI or None for the default)."""
    tree = list(_dataclass_tree(config))
    uses = isinstance(config, (TrainConfig, RegistryList, RegistryPromote, DemoConfig)) or any(
        getattr(c, "mlflow", False) is True or any(str(s).startswith("models:/") for s in getattr(c, "models", ()))
        for c in tree)
    explicit = next((c.tracking_uri for c in tree if getattr(c, "tracking_uri", None)), None)
    return uses, explicit


def _dataclass_tree(config):
    yield config
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            yield from _dataclass_tree(value)


def check_tracking_first(config) -> None:
    """A command that talks to MLflow says where, and fails within seconds when that is unreachable (instead of
    hanging in MLflow's retries for minutes)."""
    uses, explicit = tracking_of(config)
    if not uses:
        return
    from bodyschema.training.registry import check_tracking, tracking_uri

    uri = tracking_uri(explicit)
    print(f"tracking: {uri}", file=sys.stderr)
    check_tracking(uri, timeout_s=5)


# ---- the error boundary ----------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("BODYSCHEMA_DEBUG", "") not in ("", "0")
    argv = [a for a in argv if a != "--debug"]
    command = "bodyschema " + " ".join(_command_words(argv))
    try:
        config = tyro.cli(COMMANDS, prog="bodyschema", args=argv,  # a parsing error: tyro's message box, exit 2
                          description="A robot learns its body by motor babbling and perceives it by active "
                                      "inference. --debug (or BODYSCHEMA_DEBUG=1) shows the traceback behind an error.")
        return run(config)
    except KeyboardInterrupt:
        print(f"\n{command}: interrupted. Run the same command again to resume.", file=sys.stderr)
        return 130
    except expected_types() as error:
        line = explain(error)
        if line is None:                                             # e.g. a TypeError from our own code: a bug
            return _bug(command, error)
        if debug:
            traceback.print_exc()
        print(f"{command}: error: {line}", file=sys.stderr)
        return 2
    except Exception as error:
        return _bug(command, error)


def _bug(command: str, error: BaseException) -> int:
    traceback.print_exception(error)
    print(f"{command}: internal error ({type(error).__name__}): a bug, not your input. Please report it with the "
          "traceback above.", file=sys.stderr)
    return 1


def _command_words(argv: list[str]) -> list[str]:
    words = []
    for arg in argv:
        if arg not in COMMAND_WORDS:
            break
        words.append(arg)
    return words


if __name__ == "__main__":
    sys.exit(main())
