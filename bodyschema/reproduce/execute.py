"""One step: its command line parsed by the CLI itself (the same flags and checks a user meets), run in-process,
and its product: a dataset's path, a registered model's `models:/<name>/<version>`, a benchmark's run folder."""

from __future__ import annotations

import shlex
from dataclasses import dataclass

from bodyschema import log
from bodyschema.parsing import parse_command


@dataclass(frozen=True)
class Done:
    product: str
    fit_seconds: float | None = None    # a training step's fit alone (its MLflow logging excluded)
    work_seconds: float | None = None   # a benchmark's trials alone (its rows' wall_s), without loading and plots


def parse(command: str):
    """The config `bodyschema <command>` stands for."""
    return parse_command(shlex.split(command))


def run(config, progress: bool) -> Done:
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.training.config import TrainConfig

    config = log.progress_of(config, progress)
    if isinstance(config, DatagenConfig):
        from bodyschema.datagen.generate import generate

        return Done(str(generate(config, progress=progress)))
    if isinstance(config, TrainConfig):
        from bodyschema.training.train import train

        result = train(config)
        return Done(f"models:/{result.registered_name}/{result.model_version}", result.metrics.get("fit_seconds"))
    written = _benchmark_of(config).run(config)
    paths = getattr(written, "paths", written)
    work = sum(float(row.get("wall_s", 0.0)) for row in getattr(written, "rows", []))
    return Done(str(next(iter(paths.values())).parent), None, work or None)


def _benchmark_of(config):
    """The benchmark (evaluation/registry.py) whose config `config` is; only its own package is looked at (loaded
    already: the config came from it)."""
    from bodyschema.evaluation import registry

    cls = type(config)
    return next(b for b in registry.BENCHMARKS if f"{cls.__module__}.".startswith(b.module + ".") and b.config is cls)
