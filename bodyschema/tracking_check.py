"""Before a command that talks to MLflow does any work: say where, and fail within seconds when the tracking store is
unreachable (instead of hanging in MLflow's retries for minutes) or when a local store's folder is missing (or the
store, for a command that reads models), unless `--create`.
"""

from __future__ import annotations

import dataclasses
import logging

from bodyschema import log
from bodyschema.errors import must_be

logger = logging.getLogger("bodyschema.cli")


def tracking_of(config, always: bool = False) -> tuple[bool, str | None]:
    """(does this command talk to MLflow, its explicit tracking URI or None for the default). `always`: the command
    talks to MLflow whatever its config says (train, registry, demo: the `mlflow` column of bodyschema/commands.py)."""
    tree = list(dataclass_tree(config))
    uses = always or any(getattr(c, "mlflow", False) is True for c in tree) or any(
        s.startswith("models:/") for s in _specs(config))
    explicit = next((c.tracking_uri for c in tree if getattr(c, "tracking_uri", None)), None)
    return uses, explicit


def dataclass_tree(config):
    """A config and every config nested in it."""
    yield config
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            yield from dataclass_tree(value)


def reads_models(config, always: bool = False) -> bool:
    """Whether the command reads models from the tracking store (`always`: registry list/promote; a registry spec or
    a logged model directory given to a benchmark): then a store that does not exist is a mistyped URI, not a new
    store."""
    return always or any(not s.startswith(("analytic:", "trusted:")) for s in _specs(config))


def _specs(config) -> list[str]:
    """The model specs a command names: every benchmark's `models` and `encoder`."""
    specs = [s for c in dataclass_tree(config) for s in (*getattr(c, "models", ()), getattr(c, "encoder", None))]
    return [s for s in specs if isinstance(s, str)]


def check_tracking_first(config, command, create: bool = False) -> None:
    """`command`: its row of bodyschema/commands.py. `create` (`--create`): a missing local store and its folder may
    be made; refused for a command that does not talk to MLflow."""
    uses, explicit = tracking_of(config, command.mlflow)
    if not uses:
        if create:
            raise ValueError(must_be("--create", "given to a command that talks to MLflow (train, registry, demo, "
                                     "evaluate with MLflow or a models:/ spec)", "--create", "Drop it."))
        return
    from bodyschema.training.registry import check_tracking, tracking_uri
    from bodyschema.training.tracking_store import check_local_store

    uri = tracking_uri(explicit)
    log.tracking_line(uri)
    with log.timed(logger, "tracking store checked"):
        check_local_store(uri, reads=reads_models(config, command.reads_models), create=create)
        check_tracking(uri, timeout_s=5)
