"""The MLflow side of training: tracking URI and experiment, the registered versions' tags, listing, and loading.

Tracking defaults to an embedded sqlite file, `sqlite:///<cwd>/mlflow.db` (no server); `MLFLOW_TRACKING_URI`
is honoured (a `mlflow server` on 127.0.0.1, say). Models register as `bodyschema-{robot}-{modality}-{kind}`
(registration and the `champion` rule: `champion.py`). Experiments carry a description and `mlflow.experimentKind`
= `custom_model_development`, which opens MLflow's UI in its classic ML mode (not the GenAI one).

Consumers call `load("models:/<name>@champion")` (or `models:/<name>/<version>`) and get the SensoryModel
itself. Trust boundary: the artifacts are downloaded, their sha256 is compared with the digest recorded on the
registered version named by the URI (and on its logged model, which must agree; in the tracking database, never a
file beside the weights or an id in the MLmodel file), and only then are the tensors read
(`torch.load(weights_only=True)`); the MLmodel file is parsed as YAML data, no code it names is imported.

Concurrency: with the default sqlite store, creating its tables, registering a version and moving `champion` happen
under an flock on `<db>.lock` (`registry_lock`), so two `train` processes finishing together neither lose a run nor
leave the worse model as champion. With a tracking server the same lock is a file in the temp directory: it serializes
the processes of one machine only.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import urllib.parse
from dataclasses import dataclass
from pathlib import Path

import mlflow
from mlflow import MlflowClient
from mlflow.exceptions import MlflowException

from bodyschema import log
from bodyschema.base.locks import exclusive
from bodyschema.errors import must_be
from bodyschema.models.scaling import BodySpec
from bodyschema.training.digest import verify_directory, version_digest
from bodyschema.training.mlmodel_file import artifact_dir as _artifact_dir
from bodyschema.training.model_card import NOTE
from bodyschema.training.tracking_store import (  # noqa: F401 — TrackingUnreachable: importers name it here
    TrackingUnreachable,
    check_database_driver,
    check_local_store,
    check_server,
    check_sqlite_store,
    create_sqlite,
)

METRIC = "val_rmse"          # decides the champion; lower is better
VAL_TAG = "val_sha256"       # the validation data METRIC was measured on (`data.validation_digest`)
DATASET_TAG = "dataset"      # the store a version was trained on (its path); its digest: `dataset_sha256`
KIND_TAG, CLASSIC_ML = "mlflow.experimentKind", "custom_model_development"   # MLflow UI: classic ML, not GenAI
PREFIX = "bodyschema-"
_URI = re.compile(r"^models:/(?P<name>[^/@]+)(?:@(?P<alias>[^/]+)|/(?P<version>\d+))$")
# Schemes MLflow can track to ("mysql+pymysql" counts as "mysql"); anything else is a typo, refused up front.
SCHEMES = ("", "file", "sqlite", "postgresql", "mysql", "mssql", "http", "https", "databricks", "databricks-uc", "uc")
_initialized: set[str] = set()         # sqlite URIs whose tables this process created or checked under the lock


def tracking_uri(explicit: str | None = None) -> str:
    """`explicit`, else $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db."""
    return explicit or os.environ.get("MLFLOW_TRACKING_URI") or f"sqlite:///{Path.cwd() / 'mlflow.db'}"


def use_tracking(explicit: str | None = None) -> MlflowClient:
    """Point MLflow (tracking and registry) at the resolved URI, checked first; returns a client for it.

    A sqlite store is created (or migrated) once, under its file lock: two processes starting on a fresh
    directory would otherwise both run the schema migration and one would die in it."""
    uri = tracking_uri(explicit)
    check_tracking(uri)
    mlflow.set_tracking_uri(uri)
    mlflow.set_registry_uri(uri)
    if sqlite_path(uri) is None or uri in _initialized:
        return MlflowClient(uri, uri)
    with exclusive(registry_lock(uri)), log.quiet_mlflow():      # a migration's INFO lines
        if not sqlite_path(uri).exists():
            create_sqlite(sqlite_path(uri))
        client = MlflowClient(uri, uri)                       # creating the client creates or migrates the tables
        client.search_experiments(max_results=1)              # (and these make sure of it, for both stores)
        client.search_registered_models(max_results=1)
    _initialized.add(uri)
    return client


def check_tracking(uri: str, timeout_s: float = 5.0) -> None:
    """Refuse a tracking URI MLflow cannot use: an unknown scheme, a sqlite path that is a folder, a non-SQLite file
    or in a missing folder, a database URL without its driver (ValueError), or a http(s) server that does not
    answer within `timeout_s` seconds (TrackingUnreachable, a ConnectionError). Any HTTP answer counts as up."""
    if not isinstance(uri, str) or not uri:
        raise ValueError(must_be("tracking URI", "a non-empty string", uri))
    scheme = urllib.parse.urlparse(uri).scheme.split("+")[0].lower()
    if len(scheme) == 1:
        scheme = ""                          # a Windows drive letter (C:\\...): a local path
    if scheme not in SCHEMES:
        raise ValueError(must_be("tracking URI", "sqlite:///<file>.db, http(s)://<host>:<port>, file:<dir> or a "
                                 "database URL", log.masked(uri), "Fix --tracking-uri or $MLFLOW_TRACKING_URI (unset "
                                 "it for the default sqlite:///<cwd>/mlflow.db)."))
    if sqlite_path(uri) is not None:
        check_sqlite_store(sqlite_path(uri), uri)
    elif scheme in ("postgresql", "mysql", "mssql"):
        check_database_driver(uri)
    if scheme in ("http", "https"):
        check_server(uri, timeout_s)


def sqlite_path(uri: str) -> Path | None:
    """The database file of a `sqlite:///<path>` URI (relative to the cwd, as SQLAlchemy reads it), else None."""
    if not uri.startswith("sqlite:///"):
        return None
    path = uri[len("sqlite:///"):].split("?")[0]
    return Path(path) if path and path != ":memory:" else None


def registry_lock(uri: str | None = None) -> Path:
    """The lock file of a tracking store: `<db>.lock` beside a sqlite file, else one per URI in the temp dir."""
    uri = uri or mlflow.get_registry_uri()
    path = sqlite_path(uri)
    if path is not None:
        return path.with_name(path.name + ".lock")
    return Path(tempfile.gettempdir()) / f"bodyschema-registry-{hashlib.sha256(uri.encode()).hexdigest()[:16]}.lock"


def ensure_experiment(name: str, description: str | None = None) -> str:
    """The experiment id; a new experiment keeps its artifacts in <cwd>/mlartifacts unless tracking is remote.
    It carries a description (`description`, else `experiment_description(name)`) and the tag that opens MLflow's
    UI in its classic ML mode; an existing experiment gets whichever of the two it lacks (a description edited in
    the UI is kept)."""
    tags = {KIND_TAG: CLASSIC_ML, NOTE: description or experiment_description(name)}
    experiment = mlflow.get_experiment_by_name(name)
    if experiment is None:
        remote = mlflow.get_tracking_uri().startswith(("http://", "https://", "databricks"))
        location = None if remote else (Path.cwd() / "mlartifacts").as_uri()   # remote: the server decides
        try:
            return mlflow.create_experiment(name, artifact_location=location, tags=tags)
        except MlflowException:            # another process created it in between: tag it below, as any other
            experiment = mlflow.get_experiment_by_name(name)
            if experiment is None:
                raise
    for key, value in tags.items():
        if key not in experiment.tags:
            mlflow.MlflowClient().set_experiment_tag(experiment.experiment_id, key, value)
    return experiment.experiment_id


def experiment_description(name: str) -> str:
    """What an experiment holds, for one created without a description of its own."""
    if name == "bodyschema":
        return ("bodyschema: one run per `bodyschema train` (the dataset as input, params, val_rmse, loss curves, the "
                "model card and the dataset summary as artifacts, the logged model registered as "
                "`bodyschema-<robot>-<modality>-<kind>`), and evaluation runs told to log here.")
    return f"bodyschema runs logged to `{name}`."


def registered_name(robot: str, modality: str, kind: str) -> str:
    return f"{PREFIX}{robot}-{modality}-{kind}"


@dataclass(frozen=True)
class ModelRow:
    name: str
    version: str
    aliases: tuple[str, ...]
    val_rmse: float | None
    run_id: str
    created: int             # ms since epoch
    dataset: str = "?"       # the store it was trained on (its folder name; "?" for a version registered without)
    dataset_sha256: str = "?"

    def __str__(self) -> str:
        metric = "-" if self.val_rmse is None else f"{self.val_rmse:.4g}"
        return (f"{self.name}  v{self.version}  {METRIC}={metric}  dataset={self.dataset} "
                f"sha256={self.dataset_sha256[:16]}  {' '.join('@' + a for a in self.aliases)}").rstrip()


def list_models(*, tracking: str | None = None) -> list[ModelRow]:
    """Every version of every bodyschema model, by name then version, with the dataset it was trained on and that
    dataset's digest (`bodyschema registry list`)."""
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
                             int(version.creation_timestamp or 0), Path(version.tags.get(DATASET_TAG, "?")).name,
                             version.tags.get("dataset_sha256", "?")))
    return sorted(rows, key=lambda r: (r.name, int(r.version)))


def load(uri: str, *, expect_body: BodySpec | None = None, expect_modality: str | None = None,
         tracking: str | None = None):
    """The registered SensoryModel at `models:/<name>@<alias>` or `models:/<name>/<version>`, digest-checked."""
    from bodyschema.models import load_model

    check_registered_uri(uri)
    check_local_store(tracking_uri(tracking), reads=True, create=False)   # a mistyped path: not a new empty store
    client = use_tracking(tracking)
    version = resolve_version(client, uri)
    where = f"models:/{version.name}/{version.version}"
    with tempfile.TemporaryDirectory(prefix="bodyschema-load-") as tmp, log.quiet_mlflow():   # no download bars
        local = Path(mlflow.artifacts.download_artifacts(artifact_uri=where, dst_path=tmp,
                                                         tracking_uri=mlflow.get_tracking_uri()))
        model_dir = _artifact_dir(local)
        verify_directory(model_dir, version_digest(client, version), where)   # the record, never the MLmodel
        model = load_model(model_dir)
    if expect_body is not None:
        expect_body.check_compatible(model.body, f"registered model {where}")
    if expect_modality is not None and model.modality != expect_modality:
        raise ValueError(must_be(f"modality of registered model {where}", repr(expect_modality), model.modality,
                                 f"Load {registered_name(model.body.robot, expect_modality, '<kind>')} instead."))
    return model


def check_registered_uri(uri) -> None:
    """`uri` is `models:/<name>@<alias>` or `models:/<name>/<version>`."""
    if not (isinstance(uri, str) and _URI.match(uri)):
        raise ValueError(must_be("uri", "'models:/<name>@<alias>' or 'models:/<name>/<version>'", uri,
                                 "List registered models with `bodyschema registry list`."))


def resolve_version(client: MlflowClient, uri: str):
    """The ModelVersion that `models:/<name>@<alias>` or `models:/<name>/<version>` names in the tracking database."""
    check_registered_uri(uri)
    match = _URI.match(uri)
    try:
        return (client.get_model_version_by_alias(match["name"], match["alias"]) if match["alias"]
                else client.get_model_version(match["name"], match["version"]))
    except MlflowException as error:
        raise ValueError(must_be("uri", f"a registered model version in {log.masked(client.tracking_uri)}", uri,
                                 "List registered models with `bodyschema registry list`.")) from error


def load_local(path: str | Path, *, tracking: str | None = None):
    """A model directory written by `model.save`, loaded only when its digest is recorded in the tracking database
    (it was logged by `bodyschema train` there); otherwise refused, naming the explicit opt-in `trusted:<dir>`.

    The files are copied to a private temp directory first and the copy is digested and loaded, so they cannot
    change between the check and the read."""
    import shutil

    from bodyschema.models import load_model
    from bodyschema.training.digest import digest_is_recorded, directory_sha256

    path = Path(path)
    if not ((path / "meta.json").is_file() and (path / "state.pt").is_file()):
        return load_model(path)             # the house error naming what a model directory holds
    uri = tracking_uri(tracking)
    check_tracking(uri)                     # a folder or a text file as sqlite store: said so, not "recorded nowhere"
    with tempfile.TemporaryDirectory(prefix="bodyschema-local-") as tmp:
        copy = Path(shutil.copytree(path, Path(tmp) / "model", symlinks=False))
        digest = directory_sha256(copy)
        db = sqlite_path(uri)
        recorded = None if db is not None and not db.is_file() else digest_is_recorded(use_tracking(tracking), digest)
        if recorded is None:
            raise ValueError(must_be(f"model directory {str(path)!r}", f"a model logged by `bodyschema train` in {uri} "
                                     "(its sha256 recorded there)", f"sha256 {digest[:16]}… recorded nowhere",
                                     "Load it from the registry (models:/<name>@champion), point --tracking-uri at "
                                     f"the store it was trained with, or pass trusted:{path} to load it unchecked "
                                     "(tensors only, so no code runs, but its numbers are unverified)."))
        return load_model(copy)
