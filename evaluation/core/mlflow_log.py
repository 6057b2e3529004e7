"""One MLflow run per benchmark, named `<benchmark> · <model kinds> · <robot>`: the config as params (nested configs
flattened to `<field>.<name>`; `models` the specs the run used, a registry alias with the version it resolved to), a
table's numbers as metrics named `<row label>.<column>`, every file the benchmark wrote as an artifact, and per model
what its spec resolved to as tags `bodyschema.model.<i>.<spec|name|version|run_id|sha256>`.

Lineage in MLflow's own terms: every logged model the run used (a registered version's, or the one `bodyschema
train` logged with a model directory's digest) is an input of the run (`MlflowClient().get_run(id).inputs
.model_inputs`), and the run's metrics are linked to it, which is what lists the run in that model's Runs table:
the page a registered version links to as its Source Model. MLflow 3.17's run page lists as its "Logged models" only
inputs of its own experiment, and training logs to another: so each model used also has a *reference* in the
benchmark's experiment (a logged model without files, named `<registered name>-v<version>`, tagged
`bodyschema.reference.model_id`; made once per experiment and model, never a trust anchor: it carries no digest), an
input of the run as well. The datasets the models were trained on (their training runs' inputs, context `training`,
tagged with the model) and a benchmark's own target frames (context `evaluation`) are the run's dataset inputs.
The run starts when the benchmark did (`runs.benchmark_started`) and ends when it is logged, so its duration is the
benchmark's wall time; the experiment carries a description and the classic-ML kind tag (`ensure_experiment`).
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path

from bodyschema.evaluation.core.specs import provenance_rows, spec_label
from bodyschema.training.model_card import metric_name

MODEL_TAG = "bodyschema.model"
REFERENCE_TAG = "bodyschema.reference.model_id"   # a reference logged model: the id of the model it stands for
TARGETS_TAG = "bodyschema.targets"                  # `.path`, `.sha256`: the frames a benchmark scored (levels)
_SHA256 = re.compile(r"^[0-9a-f]{64}$")


def run_title(benchmark: str, models: Sequence) -> str:
    """`<benchmark> · <model kinds> · <robot>` (e.g. `levels · pixel · nao_arm`), so runs tell apart in a list."""
    if not models:
        return benchmark
    kinds = "+".join(dict.fromkeys(getattr(m, "kind", type(m).__name__) for m in models))
    return f"{benchmark} · {kinds} · {models[0].body.robot}"


def config_params(config, models: Sequence = ()) -> dict[str, str]:
    """A frozen dataclass config as MLflow params; nested configs become `<field>.<name>` at any depth (e.g.
    `perception.flow.dt`); models replace `models` by the specs used (defaults included) and add their kinds."""
    params = _flat(asdict(config))
    if models:
        params["models"] = ", ".join(spec_label(getattr(m, "provenance", {})) for m in models)
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


def logged_model_ids(client, models: Sequence) -> list[str]:
    """The MLflow logged models behind `models`, from the tracking database: a registered version's own, else every
    logged model recorded with the model's weights digest (a directory `bodyschema train` logged). Analytic
    models and unrecorded directories have none."""
    return list(used_models(client, models))


def used_models(client, models: Sequence) -> dict[str, str]:
    """logged model id → what the run used it as: `<registered name>-v<version>`, else the spec's directory name."""
    used = {}
    for model in models:
        provenance = getattr(model, "provenance", {})
        if provenance.get("name") and provenance.get("version"):
            model_id = _version_model_id(client.get_model_version(provenance["name"], provenance["version"]))
            if model_id:
                used.setdefault(model_id, f"{provenance['name']}-v{provenance['version']}")
                continue
        if _SHA256.match(provenance.get("sha256", "")):
            for model_id in _logged_with_digest(client, provenance["sha256"]):
                used.setdefault(model_id, _safe_name(Path(provenance.get("name", "model")).name or "model"))
    return used


def _safe_name(text: str) -> str:
    return re.sub(r"[/:.%\"']", "_", text)          # what MLflow refuses in a logged model's name


def _version_model_id(version) -> str | None:
    """The logged model a version was registered from: its `model_id`, which a sqlite store leaves empty, else its
    source `models:/<model id>` (as `digest.version_digest` reads it)."""
    from bodyschema.training.digest import MODEL_ID
    model_id = getattr(version, "model_id", None) or str(version.source or "").removeprefix("models:/")
    return model_id if MODEL_ID.match(model_id) else None


def _logged_with_digest(client, digest: str) -> list[str]:
    from bodyschema.training.digest import DIGEST_TAG
    experiments = [e.experiment_id for e in client.search_experiments()]
    return [m.model_id for start in range(0, len(experiments), 100)      # at most 100 experiment ids per search
            for m in client.search_logged_models(experiments[start:start + 100],
                                                 filter_string=f"tags.`{DIGEST_TAG}` = '{digest}'")]


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


def reference_model(client, experiment_id: str, model_id: str, label: str) -> str:
    """A logged model of `experiment_id` standing for logged model `model_id` of another experiment (named `label`,
    no files, no digest), found or made: what makes MLflow's run page list the model. → its id (`model_id` itself when
    it is of this experiment already)."""
    from mlflow.entities import LoggedModelStatus

    from bodyschema.training.model_card import NOTE
    original = client.get_logged_model(model_id)
    if original.experiment_id == experiment_id:
        return model_id
    found = client.search_logged_models([experiment_id], max_results=1,
                                        filter_string=f"tags.`{REFERENCE_TAG}` = '{model_id}'")
    if found:
        return found[0].model_id
    note = (f"Reference to logged model {model_id} ({original.name}) of experiment {original.experiment_id}, where its "
            f"weights, digest, training run and registered versions are: {label}. No files: made by bodyschema so that "
            "the evaluation runs of this experiment list the model they used (MLflow's run page lists the logged "
            "models of the run's own experiment only).")
    reference = client.create_logged_model(experiment_id, name=_safe_name(label), model_type="reference",
                                           tags={REFERENCE_TAG: model_id, NOTE: note})
    client.finalize_logged_model(reference.model_id, LoggedModelStatus.READY)
    return reference.model_id


def dataset_inputs(client, used: Mapping[str, str], tags: Mapping[str, str]) -> list:
    """The run's dataset inputs: every dataset the used models were trained on (their training runs' own inputs,
    context `training`, tag `model`: the models trained on it) and the target frames a benchmark scored (`tags`'
    TARGETS_TAG path and sha256, context `evaluation`)."""
    from mlflow.entities import DatasetInput, InputTag
    from mlflow.utils.mlflow_tags import MLFLOW_DATASET_CONTEXT

    found: dict[tuple[str, str], tuple] = {}                    # (name, digest) → (Dataset, [model labels])
    for model_id, label in used.items():
        run_id = client.get_logged_model(model_id).source_run_id
        for given in client.get_run(run_id).inputs.dataset_inputs if run_id else ():
            key = (given.dataset.name, given.dataset.digest)
            found.setdefault(key, (given.dataset, []))[1].append(label)
    inputs = [DatasetInput(dataset, [InputTag(MLFLOW_DATASET_CONTEXT, "training"),
                                     InputTag("model", ", ".join(labels))]) for dataset, labels in found.values()]
    if tags.get(f"{TARGETS_TAG}.sha256"):
        dataset = _local_dataset(tags[f"{TARGETS_TAG}.path"], tags[f"{TARGETS_TAG}.sha256"])
        inputs.append(DatasetInput(dataset, [InputTag(MLFLOW_DATASET_CONTEXT, "evaluation"),
                                             InputTag("sha256", tags[f"{TARGETS_TAG}.sha256"])]))
    return inputs


def _local_dataset(path: str, sha256: str):
    """A store on disk as an MLflow dataset entity (digest: its sha256's first 32 hex digits, as `train` logs it)."""
    import warnings

    from mlflow.data.dataset_source_registry import resolve_dataset_source
    from mlflow.data.meta_dataset import MetaDataset
    with warnings.catch_warnings():   # "can be interpreted in multiple ways": both are the local-file source
        warnings.filterwarnings("ignore", message=".*interpreted in multiple ways.*", category=UserWarning)
        source = resolve_dataset_source(str(Path(path).resolve()))
    return MetaDataset(source, name=Path(path).name, digest=sha256[:32])._to_mlflow_entity()


def benchmark_description(benchmark: str) -> str:
    """A benchmark's experiment's description: what it measures (the registry's help) and what a run holds."""
    from bodyschema.evaluation.registry import BENCHMARKS
    helps = [b.help for b in BENCHMARKS if b.words[-1].replace("-", "_") == benchmark]
    what = helps[0] if helps else f"the {benchmark} benchmark"
    return (f"bodyschema evaluation `{benchmark}`: {what} One run per `bodyschema evaluate` call, named `<benchmark> · "
            "<model kinds> · <robot>`: the config as params, the tables as metrics, every file written as artifacts, "
            "the models used and the datasets they were trained on as inputs.")


def log_benchmark(config, benchmark: str, metrics: Mapping[str, float], paths: Iterable[Path],
                  models: Sequence = (), tags: Mapping[str, str] | None = None, started: float | None = None) -> str:
    """Log one run of `benchmark` to `config.experiment` at `config.tracking_uri` (its models' tags, logged-model and
    dataset inputs, plus `tags`), started at `started` (s since the epoch; None: now) and ended now; → its run id."""
    import mlflow
    from mlflow.entities import LoggedModelInput

    from bodyschema.training.registry import ensure_experiment, use_tracking
    client = use_tracking(config.tracking_uri)
    used = used_models(client, models)
    shared = config.experiment == "bodyschema"                   # the training experiment: its own description
    experiment_id = ensure_experiment(config.experiment, None if shared else benchmark_description(benchmark))
    start_ms = int(1000 * (time.time() if started is None else started))
    created = client.create_run(experiment_id, start_time=start_ms, run_name=run_title(benchmark, models))
    with mlflow.start_run(run_id=created.info.run_id) as run:      # ends FAILED on an exception, else now
        mlflow.log_params(config_params(config, models))
        mlflow.set_tags({**model_tags(models), **(tags or {})})
        model_ids = list(dict.fromkeys([*used, *(reference_model(client, experiment_id, i, label)
                                                 for i, label in used.items())]))
        datasets = dataset_inputs(client, used, tags or {})
        if model_ids or datasets:  # the client's call: MLflow's fluent log_inputs refuses models outside Databricks
            client.log_inputs(run.info.run_id, datasets=datasets or None,
                              models=[LoggedModelInput(i) for i in model_ids] or None)
        now_ms = int(time.time() * 1000)            # one timestamp: the run keeps one row per metric, each model
        for model_id in model_ids or [None]:        # gets them linked
            mlflow.log_metrics(dict(metrics), step=0, timestamp=now_ms, model_id=model_id)
        for path in paths:
            mlflow.log_artifact(str(path))
        return run.info.run_id
