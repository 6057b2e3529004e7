"""The MLflow side of training: tracking URI and experiment, registration, the `champion` alias, and loading.

Tracking defaults to an embedded sqlite file, `sqlite:///<cwd>/mlflow.db` (no server); `MLFLOW_TRACKING_URI`
is honoured (a `mlflow server` on 127.0.0.1, say). Models register as `bodyschema-{robot}-{modality}-{kind}`;
the `champion` alias moves only when a new version's validation metric (`val_rmse`, lower is better) beats
the current champion's, or when a user `promote`s a version by hand.

Consumers call `load("models:/<name>@champion")` (or `models:/<name>/<version>`) and get the SensoryModel
itself. Trust boundary: the artifacts are downloaded, their sha256 is compared with the digest recorded in
the registry at logging time, and only then are the tensors read (`torch.load(weights_only=True)`).
"""

from __future__ import annotations

import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

import mlflow
from mlflow import MlflowClient
from mlflow.exceptions import MlflowException

from bodyschema.errors import must_be
from bodyschema.models.scaling import BodySpec
from bodyschema.training.mlflow_model import ARTIFACT_KEY, DIGEST_TAG, verify_directory

CHAMPION = "champion"
METRIC = "val_rmse"          # decides the champion; lower is better
PREFIX = "bodyschema-"
_URI = re.compile(r"^models:/(?P<name>[^/@]+)(?:@(?P<alias>[^/]+)|/(?P<version>\d+))$")


def tracking_uri(explicit: str | None = None) -> str:
    """`explicit`, else $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db."""
    return explicit or os.environ.get("MLFLOW_TRACKING_URI") or f"sqlite:///{Path.cwd() / 'mlflow.db'}"


def use_tracking(explicit: str | None = None) -> MlflowClient:
    """Point MLflow (tracking and registry) at the resolved URI; returns a client for it."""
    uri = tracking_uri(explicit)
    mlflow.set_tracking_uri(uri)
    mlflow.set_registry_uri(uri)
    return MlflowClient(uri, uri)


def ensure_experiment(name: str) -> str:
    """The experiment id; a new experiment keeps its artifacts in <cwd>/mlartifacts unless tracking is remote."""
    experiment = mlflow.get_experiment_by_name(name)
    if experiment is not None:
        return experiment.experiment_id
    remote = mlflow.get_tracking_uri().startswith(("http://", "https://", "databricks"))
    location = None if remote else (Path.cwd() / "mlartifacts").as_uri()   # remote: the server decides
    return mlflow.create_experiment(name, artifact_location=location)


def registered_name(robot: str, modality: str, kind: str) -> str:
    return f"{PREFIX}{robot}-{modality}-{kind}"


def update_champion(client: MlflowClient, name: str, version: str, metric: float) -> bool:
    """Move `champion` to `version` when its metric beats the current champion's (or there is none)."""
    try:
        current = client.get_model_version_by_alias(name, CHAMPION)
    except MlflowException:
        current = None
    if current is not None:
        best = float(current.tags.get(METRIC, "inf"))
        if not metric < best:
            return False
    client.set_registered_model_alias(name, CHAMPION, version)
    return True


def promote(name: str, version: str | int, *, tracking: str | None = None) -> None:
    """Point `champion` at `version` by hand (`bodyschema registry promote NAME VERSION`)."""
    client = use_tracking(tracking)
    try:
        client.get_model_version(name, str(version))
    except MlflowException as error:
        raise ValueError(must_be("NAME VERSION", "a registered model version (see `bodyschema registry list`)",
                                 f"{name} {version}")) from error
    client.set_registered_model_alias(name, CHAMPION, str(version))


@dataclass(frozen=True)
class ModelRow:
    name: str
    version: str
    aliases: tuple[str, ...]
    val_rmse: float | None
    run_id: str
    created: int             # ms since epoch

    def __str__(self) -> str:
        metric = "-" if self.val_rmse is None else f"{self.val_rmse:.4g}"
        return f"{self.name}  v{self.version}  {METRIC}={metric}  {' '.join('@' + a for a in self.aliases)}"


def list_models(*, tracking: str | None = None) -> list[ModelRow]:
    """Every version of every bodyschema model, by name then version (`bodyschema registry list`)."""
    client = use_tracking(tracking)
    rows, aliases = [], {}
    for version in client.search_model_versions(f"name LIKE '{PREFIX}%'"):
        if version.name not in aliases:      # search results do not carry aliases in every store
            by_alias = client.get_registered_model(version.name).aliases or {}
            aliases[version.name] = {str(v): sorted(a for a, w in by_alias.items() if str(w) == str(v))
                                     for v in set(map(str, by_alias.values()))}
        metric = version.tags.get(METRIC)
        rows.append(ModelRow(version.name, str(version.version),
                             tuple(aliases[version.name].get(str(version.version), ())),
                             float(metric) if metric is not None else None, version.run_id,
                             int(version.creation_timestamp or 0)))
    return sorted(rows, key=lambda r: (r.name, int(r.version)))


def load(uri: str, *, expect_body: BodySpec | None = None, expect_modality: str | None = None,
         tracking: str | None = None):
    """The registered SensoryModel at `models:/<name>@<alias>` or `models:/<name>/<version>`, digest-checked."""
    from bodyschema.models import load_model

    match = _URI.match(uri) if isinstance(uri, str) else None
    if match is None:
        raise ValueError(must_be("uri", "'models:/<name>@<alias>' or 'models:/<name>/<version>'", uri,
                                 "List registered models with `bodyschema registry list`."))
    client = use_tracking(tracking)
    name, alias = match["name"], match["alias"]
    try:
        version = (client.get_model_version_by_alias(name, alias) if alias
                   else client.get_model_version(name, match["version"]))
    except MlflowException as error:
        raise ValueError(must_be("uri", f"a registered model version in {mlflow.get_tracking_uri()}", uri,
                                 "List registered models with `bodyschema registry list`.")) from error
    where = f"models:/{name}/{version.version}"
    with tempfile.TemporaryDirectory(prefix="bodyschema-load-") as tmp:
        local = Path(mlflow.artifacts.download_artifacts(artifact_uri=where, dst_path=tmp,
                                                         tracking_uri=mlflow.get_tracking_uri()))
        model_dir = _artifact_dir(local)
        verify_directory(model_dir, version.tags.get(DIGEST_TAG), where)
        model = load_model(model_dir)
    if expect_body is not None:
        expect_body.check_compatible(model.body, f"registered model {where}")
    if expect_modality is not None and model.modality != expect_modality:
        raise ValueError(must_be(f"modality of registered model {where}", repr(expect_modality), model.modality,
                                 f"Load {registered_name(model.body.robot, expect_modality, '<kind>')} instead."))
    return model


def _artifact_dir(local: Path) -> Path:
    """Where the logged model keeps the SensoryModel directory (named in its MLmodel file), inside `local`."""
    from mlflow.models import Model

    try:
        relative = Model.load(str(local / "MLmodel")).flavors["python_function"]["artifacts"][ARTIFACT_KEY]["path"]
    except (OSError, KeyError, TypeError) as error:
        raise ValueError(must_be("registered model", f"a bodyschema pyfunc with artifact {ARTIFACT_KEY!r}",
                                 str(local), "Only models logged by `bodyschema train` can be loaded.")) from error
    path = (local / relative).resolve()
    if not path.is_relative_to(local.resolve()):
        raise ValueError(must_be(f"artifact path of {ARTIFACT_KEY!r}", "inside the model directory", relative))
    return path
