"""What the package prints, and when: the CLI's verbosity, progress bars, MLflow's chatter, debug timings.

A module logs progress and information with `logging.getLogger(__name__)` (a child of `bodyschema`) and keeps
`print` for a command's actual output, the lines a script parses (`registry list` rows, paths written). The CLI
calls `configure(verbosity)` once:

    quiet   (-1): warnings and errors only, no progress bars (the tracking-URI line stays: see `tracking_line`)
    normal   (0): our INFO lines on stderr; MLflow's own INFO chatter, run URLs and download bars silenced
    verbose  (1): DEBUG lines (configs resolved, steps timed), and MLflow's logging and bars as MLflow has them

A library call (no `configure`: a script imports bodyschema) prints nothing unless asked: no handler of ours (the
host's logging config decides), progress bars off by default (every `progress` argument defaults to False, the CLI
turns them on: `progress_bars`, `progress_of`), MLflow quiet inside our MLflow calls (`quiet_mlflow`).

MLflow reads its logging level and bar switch from the environment, tqdm its defaults when first imported (after
`configure`: the CLI imports a stage lazily), so they are set here as environment defaults; a value the user set
wins. MLflow's loggers are also set directly in case it was imported already (tests, the demo).

It imports nothing of ours but the leaf bodyschema/cli_marks.py: any stage may import it, as `bodyschema.errors`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import re
import sys
import threading
import time
from collections.abc import Iterator
from typing import Annotated

from bodyschema.cli_marks import Flag

LOGGER = "bodyschema"
QUIET, NORMAL, VERBOSE = -1, 0, 1
FLAGS = {"--quiet": QUIET, "-q": QUIET, "--verbose": VERBOSE, "-v": VERBOSE}
# MLflow's environment switches while it is not verbose (mlflow/environment_variables.py, MLflow 3)
MLFLOW_QUIET_ENV = {"MLFLOW_LOGGING_LEVEL": "WARNING", "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR": "false",
                    "MLFLOW_SUPPRESS_PRINTING_URL_TO_STDOUT": "true"}
MLFLOW_LOGGERS = ("mlflow", "alembic", "huey")
# A bar written to a file (a log, a pipe) redraws with "\r" instead of in place: one redraw per this many seconds
# there, not tqdm's 10 per second (reaching's bars left 150 redraws per controller in a log file).
FILE_BAR_INTERVAL_S = 30
# The type of a config's `progress` field: off by default (a library call prints nothing unless asked), on in the CLI
# (`progress_of`); its --help says so instead of "(default: False)".
Progress = Annotated[bool, Flag(default_hint="(default: on; off from Python)")]
_PASSWORD = re.compile(r"(?<=://)([^/@:]*):[^/@]*@")     # user:password@ of a URL
_handler: logging.Handler | None = None
_verbosity: int | None = None        # the last configure()'s; None: never configured, a library call


def split_flags(argv: list[str]) -> tuple[int, list[str]]:
    """(verbosity, argv without the global flags); the flags may stand before or after the subcommand."""
    given = [FLAGS[a] for a in argv if a in FLAGS]
    if QUIET in given and VERBOSE in given:
        from bodyschema.errors import must_be

        given_flags = " ".join(a for a in argv if a in FLAGS)
        raise ValueError(must_be("--quiet and --verbose", "given one at a time", given_flags, "Drop one of them."))
    return (given[0] if given else NORMAL), [a for a in argv if a not in FLAGS]


def configure(verbosity: int = NORMAL) -> logging.Logger:
    """Set up the `bodyschema` logger (one stderr handler, plain lines), MLflow's and tqdm's for `verbosity`."""
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
    if not _is_terminal(sys.stderr):
        os.environ.setdefault("TQDM_MININTERVAL", str(FILE_BAR_INTERVAL_S))   # every bar, ours, MLflow's
    return logger


def progress_bars() -> bool:
    """Whether to show progress bars: in the CLI unless --quiet; never by default in a library call."""
    return _verbosity is not None and _verbosity != QUIET


def progress_of(config, on: bool | None = None):
    """`config` with every `progress` flag of its tree set to `on` (default: `progress_bars()`). The CLI applies it
    to the command's config (a config's own default is the library's, off), and a command that builds configs of
    its own (the demo) to each of them."""
    on = progress_bars() if on is None else on
    changes = {f.name: progress_of(getattr(config, f.name), on) for f in dataclasses.fields(config)
               if dataclasses.is_dataclass(getattr(config, f.name)) and not isinstance(getattr(config, f.name), type)}
    if isinstance(getattr(config, "progress", None), bool):
        changes["progress"] = on
    return dataclasses.replace(config, **changes) if changes else config


@contextlib.contextmanager
def quiet_mlflow() -> Iterator[None]:
    """MLflow's INFO lines ("Creating initial MLflow database tables...") and artifact download bars off for the
    `with` body, unless the CLI is --verbose or the user chose MLflow's level / bar switch in the environment."""
    if _verbosity == VERBOSE:
        yield
        return
    loggers = [] if "MLFLOW_LOGGING_LEVEL" in os.environ else [logging.getLogger(n) for n in MLFLOW_LOGGERS]
    levels = [logger.level for logger in loggers]
    bar = "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR"
    set_bar = bar not in os.environ
    for logger in loggers:
        logger.setLevel(max(logger.getEffectiveLevel(), logging.WARNING))
    if set_bar:
        os.environ[bar] = "false"
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)
        if set_bar:
            os.environ.pop(bar, None)


@contextlib.contextmanager
def phase(desc: str, show: bool) -> Iterator[None]:
    """A bar for a phase that has nothing to count (one batched computation): `desc` and the seconds elapsed,
    redrawn every second (in a file, as rarely as any bar) until the `with` body ends; nothing unless `show`."""
    if not show:
        yield
        return
    from tqdm.auto import tqdm

    bar = tqdm(desc=desc, bar_format="{desc}: {elapsed}", leave=False)
    interval = max(1.0, getattr(bar, "mininterval", 1.0))   # a disabled bar (TQDM_DISABLE=1) has no mininterval
    stop = threading.Event()

    def redraw() -> None:
        while not stop.wait(interval):
            bar.refresh()

    ticker = threading.Thread(target=redraw, daemon=True)
    ticker.start()
    try:
        yield
    finally:
        stop.set()
        ticker.join()
        bar.close()


@contextlib.contextmanager
def timed(logger: logging.Logger, what: str) -> Iterator[None]:
    """A debug line "<what>: <seconds> s" once the `with` body is done (the clock reads cost nothing when off)."""
    start = time.perf_counter()
    yield
    logger.debug("%s: %.2f s", what, time.perf_counter() - start)


def masked(uri: str) -> str:
    """`uri` without the password of its user:password@ part (a database or server URL)."""
    return _PASSWORD.sub(r"\1:***@", uri)


def tracking_line(uri: str) -> None:
    """The tracking URI a command uses, on stderr even with --quiet: an empty registry read from the wrong
    folder's mlflow.db is otherwise silent (issue 15). It is one line, never on stdout (which scripts parse), and
    never shows a database password."""
    print(f"tracking: {masked(uri)}", file=sys.stderr)


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):      # a replaced or closed stream
        return False


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
        bars = sys.modules.get("tqdm.std")
        if bars is None:
            super().emit(record)
            return
        try:                           # a line above a live bar, not glued to its end (tqdm redraws the bar below)
            bars.tqdm.write(self.format(record), file=sys.stderr)
        except Exception:              # as logging.StreamHandler.emit: a broken stream is reported, never raised
            self.handleError(record)
