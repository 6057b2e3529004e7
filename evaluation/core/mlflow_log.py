"""One MLflow run per benchmark: the config as params (nested configs flattened to `<field>.<name>`), a table's
numbers as metrics named `<row label>.<column>`, every file the benchmark wrote as an artifact, and per model what
its spec resolved to as tags `bodyschema.model.<i>.<spec|name|version|run_id|sha256>`."""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path

from bodyschema.evaluation.core.specs import provenance_rows

MODEL_TAG = "bodyschema.model"


def metric_name(text: str) -> str:
    """`text` with every character MLflow refuses in a metric name replaced by '_'."""
    return re.sub(r"[^A-Za-z0-9_./ -]", "_", str(text))


def config_params(config, models: Sequence = ()) -> dict[str, str]:
    """A frozen dataclass config as MLflow params; nested configs become `<field>.<name>` at any depth (e.g.
    `perception.flow.dt`); models add their kinds."""
    params = _flat(asdict(config))
    if models:
        params["model_kinds"] = ",".join(f"{getattr(m, 'kind', type(m).__name__)}:{m.modality}" for m in models)
    return params


def _flat(fields: dict, prefix: str = "") -> dict[str, str]:
    params = {}
    for key, value in fields.items():
        if isinstance(value, dict):
            params.update(_flat(value, f"{prefix}{key}."))
        else:
            params[prefix + key] = str(value)
    return params


def model_tags(models: Sequence) -> dict[str, str]:
    """`bodyschema.model.<i>.<key>` → value for every model's provenance (resolved name, version, run, digest)."""
    return {f"{MODEL_TAG}.{i}.{k}": v for i, row in enumerate(provenance_rows(models)) for k, v in row.items()}


def table_metrics(table: Iterable[Mapping], label: Callable | str) -> dict[str, float]:
    """Every finite number of every row, named `<label>.<column>`; label: a column name or row → str."""
    name = (lambda row: row[label]) if isinstance(label, str) else label
    metrics = {}
    for row in table:
        prefix = metric_name(name(row))
        for key, value in row.items():
            if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
                    and key != label:
                metrics[f"{prefix}.{metric_name(key)}"] = float(value)
    return metrics


def log_benchmark(config, run_name: str, metrics: Mapping[str, float], paths: Iterable[Path],
                  models: Sequence = (), tags: Mapping[str, str] | None = None) -> str:
    """Log one run to `config.experiment` at `config.tracking_uri` (its models' tags, plus `tags`); → its run id."""
    import mlflow

    from bodyschema.training.registry import ensure_experiment, use_tracking
    use_tracking(config.tracking_uri)
    with mlflow.start_run(experiment_id=ensure_experiment(config.experiment), run_name=run_name) as run:
        mlflow.log_params(config_params(config, models))
        mlflow.set_tags({**model_tags(models), **(tags or {})})
        mlflow.log_metrics(dict(metrics))
        for path in paths:
            mlflow.log_artifact(str(path))
        return run.info.run_id
