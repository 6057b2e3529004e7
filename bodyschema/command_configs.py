"""The configs of the CLI's small commands (validate, registry list / promote): plain dataclasses, as every config."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from bodyschema.cli_marks import Positional


@dataclass(frozen=True)
class ValidateArgs:
    """Check a dataset store against the schema; exit 0 when valid, else list every problem."""

    path: Annotated[Path, Positional()]  # the .zarr store


@dataclass(frozen=True)
class RegistryList:
    """List every registered bodyschema model version with its validation metric and aliases."""

    tracking_uri: str | None = None  # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db


@dataclass(frozen=True)
class RegistryPromote:
    """Move the `champion` alias to NAME's VERSION by hand."""

    name: Annotated[str, Positional()]
    version: Annotated[int, Positional()]
    tracking_uri: str | None = None
