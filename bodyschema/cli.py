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

Start-up stays fast (bench/startup.py): this module imports only the light config dataclasses; a stage's code
(torch, MuJoCo, MLflow) is imported when its command runs, and a benchmark's config only when the command line
names it (other benchmarks stand in as empty placeholders carrying their name and help, see `commands`).

One error boundary (`main`): an expected failure (bad input, a bad file, MLflow, rendering, a non-finite
computation; the list is `bodyschema.errors.expected_types`) prints one house line on stderr and exits 2; a bug
prints its traceback and exits 1; Ctrl-C exits 130.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import re
import signal
import sys
import traceback
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Union

import tyro

from bodyschema import config_file, log, threads
from bodyschema.datagen.config import DatagenConfig
from bodyschema.datagen.importers.config import ImportConfig
from bodyschema.datagen.robot_commands import RUNNERS as ROBOT_RUNNERS, RobotCameraArgs, RobotInitArgs, RobotShowArgs
from bodyschema.demo import DemoConfig
from bodyschema.errors import expected_types, explain, must_be
from bodyschema.evaluation import registry
from bodyschema.evaluation.report import ReportConfig, write_report
from bodyschema.export_commands import RUNNERS as EXPORT_RUNNERS, ExportDatasetArgs, ExportOnnxArgs, ShowArgs
from bodyschema.reproduce.config import ReproduceConfig
from bodyschema.training.config import TrainConfig, train_commands
from bodyschema.training.sweep_config import SweepConfig, check_sweep_flags

logger = logging.getLogger("bodyschema.cli")    # not __name__: run as `python -m bodyschema.cli` it is __main__


@dataclass(frozen=True)
class ValidateArgs:
    """Check a dataset store against the schema; exit 0 when valid, else list every problem."""

    path: tyro.conf.Positional[Path]  # the .zarr store


@dataclass(frozen=True)
class RegistryList:
    """List every registered bodyschema model version with its validation metric and aliases."""

    tracking_uri: str | None = None  # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db


@dataclass(frozen=True)
class RegistryPromote:
    """Move the `champion` alias to NAME's VERSION by hand."""

    name: tyro.conf.Positional[str]
    version: tyro.conf.Positional[int]
    tracking_uri: str | None = None


COMMAND_WORDS: set[str] = set()   # every subcommand name, to name the command in an error line


def _command(name: str, kind, description: str):
    COMMAND_WORDS.add(name)
    return Annotated[kind, tyro.conf.subcommand(name, description=description)]


def _group(name: str, description: str, *members):
    """members: (name, Config, description) triples, or groups built by _group."""
    built = tuple(_command(*m) if isinstance(m, tuple) else m for m in members)
    return _command(name, Union[built], description)  # noqa: UP007 — tyro reads subcommands from typing.Union


class _Runners(Mapping):
    """Benchmarks (evaluation/registry.py) and the report: Config → runner returning the paths it wrote (levels: a
    summary holding them). Looks a config up without importing the other benchmarks' packages."""

    def _pairs(self):
        # a parsed config's package was imported to build it; the others need not be, to be told apart
        loaded = [b for b in registry.BENCHMARKS if b.module in sys.modules]
        return [(ReportConfig, write_report), *((b.config, b.run) for b in loaded)]

    def __getitem__(self, config_class):
        found = [run for cls, run in self._pairs() if cls is config_class]
        if not found:
            raise KeyError(config_class)
        return found[0]

    def __iter__(self):
        return iter([ReportConfig, *(b.config for b in registry.BENCHMARKS)])   # iterating imports them all

    def __len__(self) -> int:
        return 1 + len(registry.BENCHMARKS)


BENCHMARKS = _Runners()


def _placeholder(words: tuple[str, ...], help: str) -> type:
    """An empty stand-in for a benchmark the command line does not name: the `--help` of the groups above it shows
    only its name and help, and its real config would import its package (torch, MuJoCo) for nothing."""
    cls = dataclasses.make_dataclass("Benchmark_" + "_".join(words).replace("-", "_"), [], frozen=True)
    cls.__doc__ = help
    return cls


def _evaluate_members(named: tuple[str, ...] | None) -> list:
    """The `evaluate` subcommands, in registry order; two-word benchmarks gathered into their group. `named`: the
    words after `evaluate` on the command line (only a benchmark they name is imported); None imports all."""
    members, groups = [], {}
    for b in registry.BENCHMARKS:
        config = b.config if named is None or named[:len(b.words)] == b.words else _placeholder(b.words, b.help)
        if len(b.words) == 1:
            members.append((b.words[0], config, b.help))
        else:
            if b.words[0] not in groups:
                groups[b.words[0]] = []
                members.append(b.words[0])                               # the group's place: its first member
            groups[b.words[0]].append((b.words[1], config, b.help))
    return [m if isinstance(m, tuple) else _group(m, registry.GROUPS[m], *groups[m]) for m in members]


# Flags of `evaluate` that changed (issue 13): (command words, old flag) → the new flag, None when it is gone.
# Checked before tyro parses, so the error names the new spelling instead of "unrecognized option".
RENAMED_FLAGS = {
    (("evaluate", "reaching"), "--targets"): "--trials",
    (("evaluate", "loop-robustness"), "--reaching.targets"): "--trials",
    (("evaluate", "adaptation", "marker-shift"), "--episodes"): "--trials",
    (("evaluate", "adaptation", "jupiter"), "--episodes"): "--trials",
    (("evaluate", "self-recognition"), "--episodes"): "--trials",
    **{(("evaluate", "loop-robustness"), f"--reaching.{gone}"): None
       for gone in ("noise", "broken", "frozen", "baseline", "no-baseline", "path-plots")},
}
FLATTENED = {("evaluate", "robustness"): "--levels.", ("evaluate", "loop-robustness"): "--reaching."}   # → "--"


def check_renamed_flags(argv: list[str]) -> None:
    """The house error for a flag of `evaluate` that was renamed or flattened, naming the new flag."""
    words = tuple(_command_words(argv))
    for arg in argv[len(words):]:
        flag = arg.split("=")[0]
        prefix = FLATTENED.get(words, "\0")
        new = RENAMED_FLAGS.get((words, flag), "--" + flag[len(prefix):] if flag.startswith(prefix) else "")
        if (words, flag) in RENAMED_FLAGS and new is None:
            raise ValueError(must_be(f"flag {flag}", f"absent from `bodyschema {' '.join(words)}`", flag,
                                     "Every case of the sweep sets it; drop the flag."))
        if new:
            raise ValueError(must_be(f"flag {flag}", f"spelled {new} (renamed: --trials counts independent "
                                     "trials everywhere, and nested flags are flat)", flag,
                                     f"Use `bodyschema {' '.join(words)} {new} ...`."))


def commands(words: list[str] | None = None):
    """The tyro type of the whole CLI. `words`: the command words given (`_command_words`); a benchmark's config is
    imported only when they name it. None: every benchmark's real config (tests, `COMMANDS`)."""
    named = None if words is None else tuple(words[1:]) if words[:1] == ["evaluate"] else ()
    return Union[(  # noqa: UP007 — tyro reads subcommands from typing.Union
        _command("datagen", DatagenConfig, "Generate a motor-babbling dataset (Zarr v3)."),
        _command("validate", ValidateArgs, "Check a dataset store; exit 0 when valid, else list every problem."),
        _command("show", ShowArgs, "Summarize a dataset store and draw a contact sheet of its images (PNG)."),
        _group("robot", "A robot from a model file: write its record, look at it.",
               ("init", RobotInitArgs, "Write the robot record of an MJCF/URDF file with inferred values, to edit."),
               ("show", RobotShowArgs, "A robot's joints, sites, cameras, record and view of its ee, and a sheet."),
               ("camera", RobotCameraArgs, "Place a record's camera anew for its (edited) workspace.")),
        _command("import", ImportConfig, "Import recordings (images + CSV of angles, HDF5, LeRobot v3.0) into a "
                                         "dataset store."),
        _group("train", "Fit one sensory model on a dataset, log it to MLflow and register it. "
                        "`bodyschema train KIND --help` lists KIND's hyper-parameters with their defaults.",
               *train_commands()),
        _command("sweep", SweepConfig, "Grid or random search over a kind's hyper-parameters on Ray Tune: one MLflow "
                                       "parent run, a child per trial, the best registered (champion if better)."),
        _group("registry", "Inspect and manage the MLflow model registry.",
               ("list", RegistryList, "List registered model versions, metrics and aliases."),
               ("promote", RegistryPromote, "Move the `champion` alias to NAME's VERSION.")),
        _group("export", "Export a dataset (HDF5, LeRobot) or a model (ONNX) for other tools.",
               ("dataset", ExportDatasetArgs, "A dataset store as HDF5 or in LeRobot's v3.0 layout."),
               ("onnx", ExportOnnxArgs, "A fitted model as ONNX: rad in, prediction out, checked with onnxruntime.")),
        _group("evaluate", "Run an evaluation benchmark; each run writes results/<name>/<run-id>/ and links latest.",
               *_evaluate_members(named)),
        _command("report", ReportConfig, "Gather the latest run of every benchmark on each robot into "
                                          "results/report.md and .html, key figures first."),
        _command("demo", DemoConfig, "The end-to-end demo: babble, fit, register, perceive, reach, recognise, report."),
        _command("reproduce", ReproduceConfig, "Regenerate the README's measured tables with its own commands, "
                                               "each beside the README's figures; resumable (hours on 2 cores)."),
    )]


commands([])        # fills COMMAND_WORDS (every benchmark a placeholder: nothing heavy is imported)


def __getattr__(name: str):
    if name == "COMMANDS":                     # the full CLI type, every benchmark's config imported (tests)
        return commands(None)
    raise AttributeError(f"module 'bodyschema.cli' has no attribute {name!r}")


def run(config) -> int:
    """Run the stage a parsed config stands for; returns the process exit code."""
    check_tracking_first(config)
    if isinstance(config, DatagenConfig):
        from bodyschema.datagen.generate import generate
        from bodyschema.datagen.validate import summarize_store

        _debug_datagen(config)
        print(summarize_store(generate(config, progress=config.progress)))   # on unless --no-progress / --quiet
    elif isinstance(config, ValidateArgs):
        from bodyschema.datagen.validate import validate_store

        if not config.path.exists():     # bad input (exit 2), not an invalid store (exit 1)
            raise FileNotFoundError(must_be("path", "an existing .zarr store", str(config.path),
                                            "Create one with `bodyschema datagen --out PATH`."))
        problems = validate_store(config.path)
        for problem in problems:
            print(f"- {problem}", file=sys.stderr)
        print(f"{config.path}: {'valid' if not problems else f'{len(problems)} problem(s)'}")
        return 1 if problems else 0
    elif isinstance(config, ImportConfig):
        from bodyschema.datagen.importers.run import import_recording
        from bodyschema.datagen.validate import summarize_store

        print(summarize_store(import_recording(config)))
    elif isinstance(config, TrainConfig):
        from bodyschema.training.train import train

        print(train(config))
    elif isinstance(config, SweepConfig):
        from bodyschema.training.sweep import sweep

        print(sweep(config))
    elif isinstance(config, RegistryList):
        from bodyschema.training.registry import list_models

        rows = list_models(tracking=config.tracking_uri)
        print("\n".join(map(str, rows)) if rows else "no registered bodyschema models")
    elif isinstance(config, RegistryPromote):
        from bodyschema.training.registry import promote

        promote(config.name, config.version, tracking=config.tracking_uri)
        print(f"{config.name} v{config.version} is now @champion")
    elif type(config) in BENCHMARKS:
        written = BENCHMARKS[type(config)](config)
        paths = getattr(written, "paths", written)                         # levels: a summary holding its paths
        print("\n".join(f"{k}: {v}" for k, v in paths.items()))
    elif type(config) in EXPORT_RUNNERS:
        return EXPORT_RUNNERS[type(config)](config)
    elif type(config) in ROBOT_RUNNERS:
        return ROBOT_RUNNERS[type(config)](config)
    elif isinstance(config, DemoConfig):
        from bodyschema.demo import run_demo

        run_demo(config)
    elif isinstance(config, ReproduceConfig):
        from bodyschema.reproduce.run import reproduce

        reproduce(config)
    return 0


# ---- checks before any work ----------------------------------------------------------------------------
OLD_TRAIN_FLAGS = ("--model", "--hyper")     # `train --model KIND --hyper k v` before the kind subcommands


def check_train_flags(argv: list[str]) -> None:
    """`train --model KIND` and `--hyper k v` are gone (the kind is a subcommand, each hyper-parameter a typed
    flag of it): name the new form of the very command given, instead of tyro's "unrecognized option"."""
    if argv[:1] != ["train"] or not any(a.split("=")[0] in OLD_TRAIN_FLAGS for a in argv):
        return
    kind = argv[1] if len(argv) > 1 and not argv[1].startswith("-") else None
    words, old, rest, i = argv[1 if kind is None else 2:], [], [], 0
    while i < len(words):
        if words[i].startswith("--model="):
            kind, old, i = words[i].split("=", 1)[1], [*old, words[i]], i + 1
        elif words[i] == "--model" and i + 1 < len(words):
            kind, old, i = words[i + 1], [*old, *words[i:i + 2]], i + 2
        elif words[i] == "--hyper":
            end = next((j for j in range(i + 1, len(words)) if words[j].startswith("--")), len(words))
            old, pairs, i = [*old, *words[i:end]], words[i + 1:end], end
            rest += [w for k, v in zip(pairs[::2], pairs[1::2]) for w in _typed_flag(kind, k, v)]
        else:
            rest, i = [*rest, words[i]], i + 1
    flags = [f for f in OLD_TRAIN_FLAGS if any(w.split("=")[0] == f for w in old)]
    expected = {"--model": "the kind as a subcommand: `bodyschema train KIND`",
                "--hyper": "a typed flag of the kind's subcommand"}
    kind = kind or "KIND"
    raise ValueError(must_be(" and ".join(flags), " and ".join(expected[f] for f in flags), " ".join(old),
                             f"Use `{' '.join(['bodyschema', 'train', kind, *rest])}` "
                             f"(see `bodyschema train {kind} --help`)."))


def _typed_flag(kind: str | None, name: str, value: str) -> list[str]:
    """`--hyper name value` as the subcommand's flag: `--name value`, a list as its items, a bool as the flag."""
    from bodyschema.models import kinds

    flag = "--" + name.replace("_", "-")
    config = kinds.KINDS[kind].config_class if kind in kinds.KINDS else None
    hint = {f.name: f.type for f in dataclasses.fields(config)}.get(name) if config else None
    if hint in (bool, "bool") and value.lower() in ("true", "false"):
        return [flag if value.lower() == "true" else "--no-" + flag[2:]]
    if value.lower() in ("true", "false", "null"):
        return [flag, {"true": "True", "false": "False", "null": "None"}[value.lower()]]
    return [flag, *value.strip("[]").replace(",", " ").split()]


def tracking_of(config) -> tuple[bool, str | None]:
    """(does this command talk to MLflow, its explicit tracking URI or None for the default)."""
    tree = list(_dataclass_tree(config))
    uses = isinstance(config, (TrainConfig, SweepConfig, RegistryList, RegistryPromote, DemoConfig)) or any(
        getattr(c, "mlflow", False) is True for c in tree) or any(s.startswith("models:/") for s in _specs(config))
    explicit = next((c.tracking_uri for c in tree if getattr(c, "tracking_uri", None)), None)
    return uses, explicit


def _dataclass_tree(config):
    yield config
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            yield from _dataclass_tree(value)


def reads_models(config) -> bool:
    """Whether the command reads models from the tracking store (registry list/promote, a registry spec or a logged
    model directory given to a benchmark): then a store that does not exist is a mistyped URI, not a new store."""
    return isinstance(config, (RegistryList, RegistryPromote)) or any(
        not s.startswith(("analytic:", "trusted:")) for s in _specs(config))


def _specs(config) -> list[str]:
    """The model specs a command names: every benchmark's `models` and `encoder`."""
    specs = [s for c in _dataclass_tree(config) for s in (*getattr(c, "models", ()), getattr(c, "encoder", None))]
    return [s for s in specs if isinstance(s, str)]


_create_store = False    # `--create` (a global flag, set by `main`): the tracking check may make a local store


def check_tracking_first(config) -> None:
    """A command that talks to MLflow says where, and fails within seconds when that is unreachable (instead of
    hanging in MLflow's retries for minutes) or when a local store's folder is missing (or the store, for a command
    that reads models), unless --create."""
    uses, explicit = tracking_of(config)
    if not uses:
        if _create_store:
            raise ValueError(must_be("--create", "given to a command that talks to MLflow (train, registry, demo, "
                                     "evaluate with MLflow or a models:/ spec)", "--create", "Drop it."))
        return
    from bodyschema.training.registry import check_tracking, tracking_uri
    from bodyschema.training.tracking_store import check_local_store

    uri = tracking_uri(explicit)
    log.tracking_line(uri)
    with log.timed(logger, "tracking store checked"):
        check_local_store(uri, reads=reads_models(config), create=_create_store)
        check_tracking(uri, timeout_s=5)


def _debug_datagen(config: DatagenConfig) -> None:
    """--verbose: how the job is cut and where it runs (the shard plan depends on the config only)."""
    if not logger.isEnabledFor(logging.DEBUG):
        return
    from bodyschema.datagen.generate import chunk_len
    from bodyschema.datagen.guards import n_shards

    where = os.environ.get("RAY_ADDRESS", "a local cluster") if config.backend == "ray" else "local processes"
    logger.debug("datagen: %d samples in %d shards of %d rows; backend %s, %d workers on %s", config.n,
                 n_shards(config, chunk_len(config)), chunk_len(config), config.backend, config.workers, where)


def progress_flag(argv: list[str]) -> bool:
    """The CLI's progress bars: on unless --quiet or a --no-progress flag (any config's) was given."""
    return log.progress_bars() and not any(a.split("=")[0].endswith("no-progress") for a in argv)


# ---- the error boundary ----------------------------------------------------------------------------------
def parse_command(argv: list[str]):
    """The config a command line (after `bodyschema`, without the logging flags) stands for; a parsing error is
    tyro's message box and exit 2, a config's own check the house error."""
    check_train_flags(argv)
    check_renamed_flags(argv)
    check_sweep_flags(argv)
    argv, file = config_file.split_flag(argv)
    words = _command_words(argv)
    with _config_errors_as_ours():
        if file is None:
            return tyro.cli(commands(words), prog="bodyschema", args=argv, description=DESCRIPTION)
        command = " ".join(["bodyschema", *words])                  # --config FILE: the file's values are defaults
        config_type = config_file.command_type(commands(words), words)
        default = config_file.load_config(file, config_type, command)
        return tyro.cli(config_type, prog=command, args=argv[len(words):], default=default)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--version"]:
        print(f"bodyschema {package_version()}")
        return 0
    debug = "--debug" in argv or os.environ.get("BODYSCHEMA_DEBUG", "") not in ("", "0")
    global _create_store
    _create_store = "--create" in argv
    argv = threads.split_flag([a for a in argv if a not in ("--debug", "--create")])
    command = "bodyschema " + " ".join(_command_words([a for a in argv if a not in log.FLAGS]))
    try:
        verbosity, argv = log.split_flags(argv)
        log.configure(verbosity)
        config = log.progress_of(parse_command(argv), progress_flag(argv))   # a config's own default: the library's
        logger.debug("%s: %r", command, config)
        with log.timed(logger, command), threads.applied_for(command):     # torch threads: bodyschema/threads.py
            return run(config)
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


DESCRIPTION = ("A robot learns its body by motor babbling and perceives it by active inference. --debug (or "
               "BODYSCHEMA_DEBUG=1) shows the traceback behind an error; --quiet: warnings only, no progress bars; "
               "--verbose: debug lines (configs resolved, steps timed) and MLflow's own logging; --create: a command "
               "that talks to MLflow may create a local tracking store and its folder; --threads N (or "
               "BODYSCHEMA_THREADS): torch's threads, by default measured, 1 on a busy machine (each before or after "
               "the subcommand). `<command> --config FILE`: its fields from a TOML/YAML file or a run.json, flags "
               "override the file; --version: the package's version.")
# tyro names a nested subcommand's inner dataclass `__tyro-dummy-inner__` (and its flags `__tyro_dummy_inner__.x`);
# a value error raised while it builds the config can carry that name, which means nothing to a user.
TYRO_DUMMY = re.compile(r"_{1,2}tyro[-_]dummy[-_]inner_{1,2}[.\-_]?")


def strip_tyro_names(line: str) -> str:
    """An error line without tyro's internal names."""
    return TYRO_DUMMY.sub("", line)


class ConfigRejected(ValueError):
    """A config's own check (`__post_init__`) refused the parsed values: shown as the house error line."""


@contextlib.contextmanager
def _config_errors_as_ours():
    """Route a config's `__post_init__` ValueError, which tyro would box as "Error parsing __tyro-dummy-inner__...:
    <message>", to our error boundary (one house line, exit 2). Uses tyro's parse-error hook (tyro._errors, private:
    absent in other tyro versions, where tyro's own box remains); an error tied to one flag keeps tyro's box, which
    shows that flag's help."""
    try:
        from tyro import _errors as tyro_errors
        hook, failure = tyro_errors.on_parse_error, tyro_errors.InstantiationFailure
    except (ImportError, AttributeError):
        yield
        return

    def reject(event) -> None:
        if isinstance(event, failure) and event.argument is None:
            raise ConfigRejected(strip_tyro_names(event.message))

    with hook(reject):
        yield


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


def _command_words(argv: list[str]) -> list[str]:
    known = COMMAND_WORDS | {w for b in registry.BENCHMARKS for w in b.words}   # a benchmark registered since import
    words = []
    for arg in argv:
        if arg not in known:
            break
        words.append(arg)
    return words


if __name__ == "__main__":
    sys.exit(main())
