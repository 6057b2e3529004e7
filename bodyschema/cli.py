"""`bodyschema <stage> ...`: one CLI over the pipeline's frozen dataclass configs (tyro).

    bodyschema datagen --robot nao_arm --n 2000 --sampler babble --workers 2 --out data/nao.zarr
    bodyschema validate data/nao.zarr
    bodyschema train --model gpr --data data/nao.zarr --modality ee_xyz
    bodyschema registry list | bodyschema registry promote NAME VERSION
    bodyschema evaluate levels --model models:/bodyschema-nao_arm-ee_xyz-gpr@champion --levels 1 2 3
    bodyschema evaluate reaching --robot nao_arm | evaluate adaptation jupiter | evaluate self-recognition
    bodyschema report
    bodyschema demo
"""

from __future__ import annotations

import sys
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


def _command(name: str, kind, description: str):
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
    if isinstance(config, DatagenConfig):
        from bodyschema.datagen.generate import generate
        from bodyschema.datagen.validate import summarize_store

        print(summarize_store(generate(config)))
    elif isinstance(config, ValidateArgs):
        from bodyschema.datagen.validate import validate_store

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


def main(argv: list[str] | None = None) -> int:
    try:
        config = tyro.cli(COMMANDS, prog="bodyschema", args=argv,
                          description="A robot learns its body by motor babbling and perceives it by active inference.")
        return run(config)
    except (ValueError, OSError) as error:
        # User-facing errors are already in the house form; no traceback for them.
        print(f"error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
