"""Registration and the `champion` alias: a logged model becomes a version of `bodyschema-{robot}-{modality}-{kind}`,
and `champion` moves only when a new version's validation metric (`val_rmse`, lower is better) beats the current
champion's *on the same validation data* (tag `val_sha256`: the store's digest and its held-out rows; a version
registered before that tag is compared by its `dataset_sha256`), or when a user `promote`s a version by hand. A version
scored on another store (an imported one beside a simulated one) never moves `champion` by itself.

Concurrency: registering a version (with its tags, in one transaction) and moving `champion` (a compare-and-set)
happen under the registry lock (`registry.registry_lock`), so two `train` processes finishing together neither lose a
run nor leave the worse model as champion.
"""

from __future__ import annotations

import contextlib
import io
import logging

import mlflow
from mlflow import MlflowClient
from mlflow.exceptions import MlflowException

from bodyschema.base.locks import exclusive
from bodyschema.errors import must_be
from bodyschema.training.digest import DIGEST_TAG
from bodyschema.training.model_card import describe_registration
from bodyschema.training.registry import METRIC, VAL_TAG, registry_lock, use_tracking

CHAMPION = "champion"
_log = logging.getLogger(__name__)


def register_version(client: MlflowClient, name: str, model_uri: str, tags: dict[str, str],
                     metric: float) -> tuple[str, bool]:
    """Register logged model `model_uri` as a version of `name`, its tags set in the same transaction, describe the
    version and `name` (kind, body, modality, data digest: `model_card`), then move `champion` if `metric` is
    better — all under the registry lock. → (version, now champion?)

    Idempotent, so a command started again after a kill (or after it finished) converges: a version of `name`
    that already holds these very weights (same DIGEST_TAG) is reused, never duplicated; a version of the same
    run without a digest (left by a kill between creating and tagging, before tags moved into the creation)
    could never load and is deleted."""
    digest = tags[DIGEST_TAG]
    with exclusive(registry_lock()):
        run_id = client.get_logged_model(model_uri.removeprefix("models:/")).source_run_id
        if _registered_model_exists(client, name):
            for stale in client.search_model_versions(f"name = '{name}' and run_id = '{run_id}'"):
                if DIGEST_TAG not in stale.tags:
                    client.delete_model_version(name, stale.version)
            same = client.search_model_versions(f"name = '{name}' and tags.`{DIGEST_TAG}` = '{digest}'")
        else:
            same = []
        if same:
            version = str(min(int(v.version) for v in same))
        else:
            version = _register_quietly(model_uri, name, tags)
        describe_registration(client, name, version, tags, model_uri.removeprefix("models:/"))
        return version, _champion_if_better(client, name, version, metric, tags)


def _register_quietly(model_uri: str, name: str, tags: dict[str, str]) -> str:
    """`mlflow.register_model`, whose own prints on stderr ("Created version '1' of model ...") become DEBUG lines
    of our logger, shown with --verbose only: `train` prints the version it registered itself. → the new version"""
    printed = io.StringIO()
    with contextlib.redirect_stderr(printed):            # MLflow's eprint writes to the current sys.stderr
        version = mlflow.register_model(model_uri, name, tags=tags, await_registration_for=60).version
    for line in filter(str.strip, printed.getvalue().splitlines()):
        _log.debug(line)
    return str(version)


def update_champion(client: MlflowClient, name: str, version: str, metric: float) -> bool:
    """Move `champion` to `version` when its metric beats the current champion's (or there is none): a
    compare-and-set under the registry lock, so of two runs finishing together the better one ends champion."""
    with exclusive(registry_lock()):
        return _champion_if_better(client, name, version, metric, client.get_model_version(name, version).tags)


def same_validation_data(a: dict[str, str], b: dict[str, str]) -> bool:
    """Two versions' val_rmse compare only when measured on the same validation data: the same `val_sha256`; a
    version registered before that tag counts by its `dataset_sha256` (same store, same split settings assumed)."""
    if VAL_TAG in a and VAL_TAG in b:
        return a[VAL_TAG] == b[VAL_TAG]
    return bool(a.get("dataset_sha256")) and a.get("dataset_sha256") == b.get("dataset_sha256")


def _champion_if_better(client: MlflowClient, name: str, version: str, metric: float, tags: dict[str, str]) -> bool:
    # Caller holds the registry lock: the read and the write below are one step for every bodyschema process.
    try:
        current = client.get_model_version_by_alias(name, CHAMPION)
    except MlflowException:
        current = None
    if current is not None:
        if str(current.version) == str(version):
            return True
        if not same_validation_data(current.tags, tags):
            _log.info("%s: @champion stays v%s, scored on other validation data (dataset %s…, v%s's %s…): the "
                      "scores do not compare. Move it by hand with `bodyschema registry promote %s %s`.", name,
                      current.version, str(current.tags.get("dataset_sha256", "?"))[:12], version,
                      str(tags.get("dataset_sha256", "?"))[:12], name, version)
            return False
        best = float(current.tags.get(METRIC, "inf"))
        if not metric < best:
            return False
    client.set_registered_model_alias(name, CHAMPION, version)
    return True


def _registered_model_exists(client: MlflowClient, name: str) -> bool:
    try:
        client.get_registered_model(name)
        return True
    except MlflowException:
        return False


def promote(name: str, version: str | int, *, tracking: str | None = None) -> None:
    """Point `champion` at `version` by hand (`bodyschema registry promote NAME VERSION`)."""
    client = use_tracking(tracking)
    try:
        client.get_model_version(name, str(version))
    except MlflowException as error:
        raise ValueError(must_be("NAME VERSION", "a registered model version (see `bodyschema registry list`)",
                                 f"{name} {version}")) from error
    with exclusive(registry_lock()):
        client.set_registered_model_alias(name, CHAMPION, str(version))
