"""What the CLI's commands run (bodyschema/commands.py's `run` column, by name: see there why).

Each runner takes its parsed config and returns the exit code (None: 0). A stage's code (torch, MuJoCo, MLflow) is
imported inside its runner, so building the CLI imports none of it.
"""

from __future__ import annotations

import logging
import os
import sys

from bodyschema.command_configs import RegistryList, RegistryPromote, ValidateArgs
from bodyschema.errors import must_be

logger = logging.getLogger("bodyschema.cli")    # its debug lines are the CLI's (--verbose)


def run_datagen(config) -> None:
    from bodyschema.datagen.generate import generate
    from bodyschema.datagen.store.validate import summarize_store

    _debug_datagen(config)
    print(summarize_store(generate(config, progress=config.progress)))   # on unless --no-progress / --quiet


def run_validate(config: ValidateArgs) -> int:
    from bodyschema.datagen.store.validate import validate_store

    if not config.path.exists():     # bad input (exit 2), not an invalid store (exit 1)
        raise FileNotFoundError(must_be("path", "an existing .zarr store", str(config.path),
                                        "Create one with `bodyschema datagen --out PATH`."))
    problems = validate_store(config.path)
    for problem in problems:
        print(f"- {problem}", file=sys.stderr)
    print(f"{config.path}: {'valid' if not problems else f'{len(problems)} problem(s)'}")
    return 1 if problems else 0


def run_import(config) -> None:
    from bodyschema.datagen.exchange.importers.run import import_recording
    from bodyschema.datagen.store.validate import summarize_store

    print(summarize_store(import_recording(config)))


def run_train(config) -> None:
    from bodyschema.training.train import train

    print(train(config))


def run_sweep(config) -> None:
    from bodyschema.training.sweep import sweep

    print(sweep(config))


def run_registry_list(config: RegistryList) -> None:
    from bodyschema.training.registry import list_models

    rows = list_models(tracking=config.tracking_uri)
    print("\n".join(map(str, rows)) if rows else "no registered bodyschema models")


def run_registry_promote(config: RegistryPromote) -> None:
    from bodyschema.training.champion import promote

    promote(config.name, config.version, tracking=config.tracking_uri)
    print(f"{config.name} v{config.version} is now @champion")


def run_demo(config) -> None:
    from bodyschema.demo import run_demo

    run_demo(config)


def run_reproduce(config) -> None:
    from bodyschema.reproduce.run import reproduce

    reproduce(config)


def _debug_datagen(config) -> None:
    """--verbose: how the job is cut and where it runs (the shard plan depends on the config only)."""
    if not logger.isEnabledFor(logging.DEBUG):
        return
    from bodyschema.datagen.guards import n_shards
    from bodyschema.datagen.shards import chunk_len

    where = os.environ.get("RAY_ADDRESS", "a local cluster") if config.backend == "ray" else "local processes"
    logger.debug("datagen: %d samples in %d shards of %d rows; backend %s, %d workers on %s", config.n,
                 n_shards(config, chunk_len(config)), chunk_len(config), config.backend, config.workers, where)
