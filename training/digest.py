"""What a saved model is trusted by: its content digest, as recorded in the tracking database at logging time.

The artifact store (a folder or bucket of files) is treated as editable by others; the tracking database (sqlite
file or tracking server) is the anchor of trust. `bodyschema train` records `directory_sha256` of the saved model
directory (`meta.json` + `state.pt`) in the database — as a tag of the MLflow logged model, of the run and of the
registered version — and every loader recomputes the digest of the files it got and compares it with the
recorded one before reading a tensor. Nothing stored beside the weights (a digest file, the MLmodel file, a run
directory sidecar) is ever used as the reference: whoever can edit the weights can edit that too.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from bodyschema.errors import must_be

DIGEST_TAG = "bodyschema.model_sha256"
MODEL_ID = re.compile(r"^m-[0-9a-f]{32}$")      # an MLflow 3 logged model id
NO_DIGEST_HINT = "Only models logged by `bodyschema train` (which records their digest) can be loaded."


def directory_sha256(path: str | Path) -> str:
    """sha256 over the sorted relative paths and bytes of every file under `path` (the saved model)."""
    path = Path(path)
    digest = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file())
    if not files:
        raise FileNotFoundError(must_be("model directory", "a directory holding meta.json and state.pt", str(path),
                                        "Nothing to digest: pass the directory given to model.save()."))
    for file in files:
        digest.update(file.relative_to(path).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(file.read_bytes()).digest())
    return digest.hexdigest()


def verify_directory(path: str | Path, expected: str | None, where: str) -> None:
    """Raise unless the model directory's digest equals `expected` (recorded in the tracking database)."""
    if not expected:
        raise ValueError(must_be(f"{where}", f"recorded with a {DIGEST_TAG} in the tracking database",
                                 "no recorded digest", NO_DIGEST_HINT))
    actual = directory_sha256(path)
    if actual != expected:
        raise ValueError(must_be(f"the sha256 of the files of {where}",
                                 f"{expected[:16]}…, the digest the tracking database recorded for it",
                                 f"{actual[:16]}…", "Its artifact store was edited, holds another model's files or a "
                                 "partial copy: refusing to load them. Restore the artifacts, or train and register "
                                 "the model again (`bodyschema train`)."))


def version_digest(client, version) -> str:
    """The digest recorded at registration for registered `version` (a ModelVersion read from the tracking database),
    which its logged model, named by the version's own record (never by an MLmodel file), must repeat."""
    where = f"models:/{version.name}/{version.version}"
    recorded = version.tags.get(DIGEST_TAG)
    if not recorded:
        raise ValueError(must_be(where, f"recorded with a {DIGEST_TAG} in the tracking database",
                                 "no recorded digest", NO_DIGEST_HINT))
    model_id = getattr(version, "model_id", None) or str(version.source or "").removeprefix("models:/")
    if MODEL_ID.match(model_id):
        logged = logged_model_digest(client, model_id)
        if logged != recorded:
            raise ValueError(must_be(f"recorded digests of {where}", "one value", [recorded, logged],
                                     "The tracking database disagrees with itself; refusing to load."))
    return recorded


def logged_model_digest(client, model_id: str) -> str:
    """The digest the tracking database holds for logged model `model_id`: its own tag, which every registered
    version made from it must repeat (a version tagged otherwise is a conflict, refused)."""
    from mlflow.exceptions import MlflowException

    where = f"logged model models:/{model_id}"
    try:
        logged = client.get_logged_model(model_id)
    except MlflowException as error:
        raise ValueError(must_be(where, "a logged model of the current tracking store",
                                 "not found", "Set MLFLOW_TRACKING_URI to the store the model was logged in.")) \
            from error
    recorded = logged.tags.get(DIGEST_TAG)
    versions = [v for v in client.search_model_versions(f"run_id = '{logged.source_run_id}'")
                if v.source == f"models:/{model_id}"] if logged.source_run_id else []
    found = {recorded} | {v.tags.get(DIGEST_TAG) for v in versions}
    found.discard(None)
    if len(found) > 1:
        raise ValueError(must_be(f"recorded digests of {where}", "one value", sorted(found),
                                 "The tracking database disagrees with itself; refusing to load."))
    if not found:
        raise ValueError(must_be(where, f"recorded with a {DIGEST_TAG} in the tracking database",
                                 "no recorded digest", NO_DIGEST_HINT))
    return found.pop()


def digest_is_recorded(client, digest: str) -> str | None:
    """Where the tracking database records `digest` (a registered version or a logged model), else None."""
    condition = f"tags.`{DIGEST_TAG}` = '{digest}'"
    for version in client.search_model_versions(condition, max_results=1):
        return f"models:/{version.name}/{version.version}"
    experiments = [e.experiment_id for e in client.search_experiments()]
    for start in range(0, len(experiments), 100):            # search_logged_models takes at most 100 ids
        for model in client.search_logged_models(experiments[start:start + 100], filter_string=condition,
                                                 max_results=1):
            return f"models:/{model.model_id}"
    return None

