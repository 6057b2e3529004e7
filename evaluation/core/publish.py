"""The end of every benchmark run: the models it used (`models.csv`: spec, registered name, version, source run,
weights digest) beside its tables, one MLflow run (when `config.mlflow`), and `<out>/latest` moved to the run."""

from __future__ import annotations

from collections.abc import Mapping, MutableMapping, Sequence
from pathlib import Path

from bodyschema.evaluation.core.mlflow_log import log_benchmark
from bodyschema.evaluation.core.runs import MODELS_CSV, benchmark_started, mark_latest, record_robot
from bodyschema.evaluation.core.specs import provenance_rows
from bodyschema.evaluation.core.tables import write_csv


def publish(config, folder: Path, name: str, metrics: Mapping[str, float], paths: MutableMapping[str, Path],
            models: Sequence = (), tags: Mapping[str, str] | None = None) -> str | None:
    """Write models.csv into `folder` (added to `paths`), log the run of benchmark `name` (named `<name> · <model
    kinds> · <robot>`, with extra `tags`, e.g. the digest of a target store) and mark it latest; → MLflow run id or
    None."""
    if models:
        paths["models_csv"] = write_csv(provenance_rows(models), folder / MODELS_CSV)
    started = benchmark_started(folder)                  # read (and its mark cleared) whether logged or not
    run_id = log_benchmark(config, name, metrics, paths.values(), models, tags, started) if config.mlflow else None
    if models:
        record_robot(folder, models[0].body.robot)
    mark_latest(folder)
    return run_id
