"""`bodyschema <stage> ...`: one CLI over the pipeline's frozen dataclass configs (tyro).

    bodyschema datagen --robot nao_arm --n 2000 --sampler babble --workers 2 --out data/nao.zarr
    bodyschema validate data/nao.zarr | bodyschema show data/nao.zarr   (summary + contact sheet PNG)
    bodyschema robot init arm.urdf | bodyschema robot show arm.urdf   (a robot from a file: its record, a look)
    bodyschema import recording/ --angles deg --robot nao_arm --out data/real.zarr   (images + CSV, HDF5, LeRobot)
    bodyschema export dataset --to lerobot|hdf5 data/nao.zarr OUT | bodyschema export onnx MODEL_SPEC OUT.onnx
    bodyschema train gpr --data data/nao.zarr --modality ee_xyz --noise-floor 1e-6   (train KIND --help: its flags)
    bodyschema registry list | bodyschema registry promote NAME VERSION
    bodyschema evaluate levels --model models:/bodyschema-nao_arm-ee_xyz-gpr@champion --levels 1 2 3
    bodyschema evaluate reaching --robot nao_arm | evaluate adaptation jupiter | evaluate self-recognition
    bodyschema report
    bodyschema demo
    bodyschema reproduce --only levels   (the README's tables from its own commands, beside its figures)
    bodyschema evaluate levels --config levels.toml --trials 50   (any command: TOML/YAML/run.json, flags override)
    bodyschema --version
    bodyschema --debug ...    (or BODYSCHEMA_DEBUG=1): show the traceback behind an error message
    bodyschema --quiet ... | --verbose ...   (before or after the subcommand): warnings only, no progress bars |
                              debug lines (configs resolved, steps timed) and MLflow's own logging (bodyschema/log.py)
    bodyschema --threads N ...   (or BODYSCHEMA_THREADS=N): torch's intra-op threads; by default measured, 1 on a busy
                              machine (bodyschema/threads.py; --verbose says the count and why)
    bodyschema --create ...   a command that talks to MLflow may create its local tracking store and the store's
                              folder (else a mistyped URI is an error, not a new empty registry)

Start-up stays fast (bench/startup.py): the commands are a table of light config dataclasses
(bodyschema/commands.py); a stage's code (torch, MuJoCo, MLflow) is imported when its command runs
(bodyschema/runners.py), and a benchmark's config only when the command line names it. The configs know nothing of
tyro: their CLI marks (bodyschema/cli_marks.py) become tyro's in bodyschema/tyro_marks.py.

One error boundary (`main`): an expected failure (bad input, a bad file, MLflow, rendering, a non-finite
computation; the list is `bodyschema.errors.expected_types`) prints one house line on stderr and exits 2; a bug
prints its traceback and exits 1; Ctrl-C exits 130.
"""

from __future__ import annotations

import logging
import os
import re
import signal
import sys
import traceback

from bodyschema import commands, log, threads
from bodyschema.errors import expected_types, explain
from bodyschema.parsing import parse_command
from bodyschema.tracking_check import check_tracking_first

logger = logging.getLogger("bodyschema.cli")    # not __name__: run as `python -m bodyschema.cli` it is __main__


def run(command: commands.Command, config, create: bool = False) -> int:
    """Run `command` (its row of the table) on its parsed config; the process exit code. `create`: `--create`."""
    check_tracking_first(config, command, create)
    return command.run(config) or 0


def progress_flag(argv: list[str]) -> bool:
    """The CLI's progress bars: on unless --quiet or a --no-progress flag (any config's) was given."""
    return log.progress_bars() and not any(a.split("=")[0].endswith("no-progress") for a in argv)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--version"]:
        print(f"bodyschema {package_version()}")
        return 0
    debug = "--debug" in argv or os.environ.get("BODYSCHEMA_DEBUG", "") not in ("", "0")
    create = "--create" in argv
    argv = threads.split_flag([a for a in argv if a not in ("--debug", "--create")])
    words = commands.words_of([a for a in argv if a not in log.FLAGS])
    command = "bodyschema " + " ".join(words)
    try:
        verbosity, argv = log.split_flags(argv)
        log.configure(verbosity)
        config = log.progress_of(parse_command(argv), progress_flag(argv))   # a config's own default: the library's
        logger.debug("%s: %r", command, config)
        with log.timed(logger, command), threads.applied_for(command):     # torch threads: bodyschema/threads.py
            return run(commands.find(words), config, create)
    except KeyboardInterrupt:
        print(f"\n{command}: interrupted. {after_interrupt(command)}", file=sys.stderr)
        return 130
    except BrokenPipeError:                                          # `bodyschema ... --help | head`: the reader left
        return _stdout_closed()
    except expected_types() as error:
        line = explain(error)
        if line is None:                                             # e.g. a TypeError from our own code: a bug
            return _bug(command, error)
        if debug:
            traceback.print_exc()
        print(f"{command}: error: {log.masked(strip_tyro_names(line))}", file=sys.stderr)   # a URL's password
        return 2
    except Exception as error:
        return _bug(command, error)


def package_version() -> str:
    """The installed distribution's version (`bodyschema --version`)."""
    import importlib.metadata
    try:
        return importlib.metadata.version("bodyschema")
    except importlib.metadata.PackageNotFoundError:
        return "unknown (not installed)"


RESUMING = ("datagen", "train", "sweep", "reproduce")   # they keep finished shards / checkpoints / steps
ATOMIC = ("export", "import", "show")       # they write beside OUT and rename: an interrupted one left nothing


def after_interrupt(command: str) -> str:
    """What is true after Ctrl-C of `command` ("bodyschema <words>"), for the line that says it was interrupted."""
    word = (command.split()[1:2] or [""])[0]
    if word in RESUMING:
        return "Run the same command again to resume."
    if word in ATOMIC:
        return "Nothing was written; run the same command again."
    if word == "demo":                      # its datasets are made with --overwrite; train reuses or resumes a fit
        return "Run the same command again: it remakes the datasets, reuses or resumes the fits, reruns the rest."
    return "Run the same command again; it starts over."


# tyro names a nested subcommand's inner dataclass `__tyro-dummy-inner__` (and its flags `__tyro_dummy_inner__.x`);
# a value error raised while it builds the config can carry that name, which means nothing to a user.
TYRO_DUMMY = re.compile(r"_{1,2}tyro[-_]dummy[-_]inner_{1,2}[.\-_]?")


def strip_tyro_names(line: str) -> str:
    """An error line without tyro's internal names."""
    return TYRO_DUMMY.sub("", line)


def _stdout_closed() -> int:
    """Stdout's reader went away (`| head`): nothing to say, and nothing more to write (Python's flush at exit would
    raise again: stdout now goes to /dev/null). The status of a process killed by SIGPIPE, as `seq 1 1e6 | head`."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):   # a replaced stdout (tests) has no file descriptor
        pass
    return 128 + signal.SIGPIPE


def _bug(command: str, error: BaseException) -> int:
    traceback.print_exception(error)
    print(f"{command}: internal error ({type(error).__name__}): a bug, not your input. Please report it with the "
          "traceback above.", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
