"""Verbosity of the CLI: one `bodyschema` logger, configured once by `bodyschema.cli.main`.

A module logs progress and information with `logging.getLogger(__name__)` (a child of `bodyschema`) and keeps
`print` for a command's actual output, the lines a script parses (`registry list` rows, paths written). The CLI
calls `configure(verbosity)` once:

    quiet   (-1): warnings and errors only, no progress bars (the tracking-URI line stays: see `tracking_line`)
    normal   (0): our INFO lines on stderr; MLflow's own INFO chatter, run URLs and download bars silenced
    verbose  (1): DEBUG lines, and MLflow's logging and bars as MLflow configures them

MLflow reads its logging level and bar switch from the environment when it is first imported (it is imported
lazily, after this runs), so they are set here as environment defaults; a value the user set wins. Its loggers
are also set directly in case it was imported already (tests, the demo).
"""

from __future__ import annotations

import logging
import os
import sys

LOGGER = "bodyschema"
QUIET, NORMAL, VERBOSE = -1, 0, 1
FLAGS = {"--quiet": QUIET, "-q": QUIET, "--verbose": VERBOSE, "-v": VERBOSE}
# MLflow's environment switches while it is not verbose (mlflow/environment_variables.py, MLflow 3)
MLFLOW_QUIET_ENV = {"MLFLOW_LOGGING_LEVEL": "WARNING", "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR": "false",
                    "MLFLOW_SUPPRESS_PRINTING_URL_TO_STDOUT": "true"}
MLFLOW_LOGGERS = ("mlflow", "alembic", "huey")
_handler: logging.Handler | None = None
_verbosity = NORMAL                  # the last configure()'s


def split_flags(argv: list[str]) -> tuple[int, list[str]]:
    """(verbosity, argv without the global flags); the flags may stand before or after the subcommand."""
    given = [FLAGS[a] for a in argv if a in FLAGS]
    if QUIET in given and VERBOSE in given:
        from bodyschema.errors import must_be

        given_flags = " ".join(a for a in argv if a in FLAGS)
        raise ValueError(must_be("--quiet and --verbose", "given one at a time", given_flags, "Drop one of them."))
    return (given[0] if given else NORMAL), [a for a in argv if a not in FLAGS]


def configure(verbosity: int = NORMAL) -> logging.Logger:
    """Set up the `bodyschema` logger (one stderr handler, plain lines) and MLflow's for `verbosity`."""
    global _handler, _verbosity
    _verbosity = verbosity
    logger = logging.getLogger(LOGGER)
    if _handler is None or _handler not in logger.handlers:
        _handler = _StderrHandler()
        _handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(_handler)
    logger.setLevel({QUIET: logging.WARNING, NORMAL: logging.INFO, VERBOSE: logging.DEBUG}[verbosity])
    # propagate stays on: a host application's (or pytest's caplog) root handlers see our records too; the CLI
    # leaves the root logger without handlers, so each line is printed once.
    if verbosity < VERBOSE:
        for name, value in MLFLOW_QUIET_ENV.items():
            os.environ.setdefault(name, value)
        for name in MLFLOW_LOGGERS:
            logging.getLogger(name).setLevel(logging.WARNING)
    if verbosity == QUIET:
        os.environ.setdefault("TQDM_DISABLE", "1")    # bars a config has no `progress` flag for (tqdm ≥ 4.66)
    return logger


def progress_bars() -> bool:
    """Whether to show progress bars where a config has no `progress` flag of its own (off with --quiet)."""
    return _verbosity != QUIET


def progress_of(config):
    """`config` with every `progress` flag in its tree off under --quiet; as it is otherwise. The CLI applies it
    to the command's config, and a command that builds configs of its own (the demo) to each of them."""
    return _without_progress(config) if _verbosity == QUIET else config


def _without_progress(config):
    import dataclasses
    changes = {f.name: _without_progress(getattr(config, f.name)) for f in dataclasses.fields(config)
               if dataclasses.is_dataclass(getattr(config, f.name)) and not isinstance(getattr(config, f.name), type)}
    if getattr(config, "progress", None) is True:
        changes["progress"] = False
    return dataclasses.replace(config, **changes) if changes else config


def tracking_line(uri: str) -> None:
    """The tracking URI a command uses, on stderr even with --quiet: an empty registry read from the wrong
    folder's mlflow.db is otherwise silent (issue 15). It is one line and never on stdout, which scripts parse."""
    print(f"tracking: {uri}", file=sys.stderr)


class _StderrHandler(logging.StreamHandler):
    """A stream handler that writes to the *current* sys.stderr (pytest's capsys swaps it after configure)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:   # logging.StreamHandler.__init__ assigns it; the property always wins
        pass

    def emit(self, record: logging.LogRecord) -> None:
        sys.stdout.flush()             # output printed before this line appears before it, also when both go to a file
        super().emit(record)
