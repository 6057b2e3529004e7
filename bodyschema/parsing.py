"""A command line (after `bodyschema`) → the config it stands for, by the command table and tyro.

Below the CLI's error boundary (cli.py) and above the table (commands.py): `bodyschema reproduce` parses each
step's command line here, with the same flags and checks a user meets, without importing the CLI that runs it.
"""

from __future__ import annotations

from bodyschema import commands, config_file, tyro_marks
from bodyschema.training.sweep_config import check_sweep_flags

DESCRIPTION = ("A robot learns its body by motor babbling and perceives it by active inference. --debug (or "
               "BODYSCHEMA_DEBUG=1) shows the traceback behind an error; --quiet: warnings only, no progress bars; "
               "--verbose: debug lines (configs resolved, steps timed) and MLflow's own logging; --create: a command "
               "that talks to MLflow may create a local tracking store and its folder; --threads N (or "
               "BODYSCHEMA_THREADS): torch's threads, by default measured, 1 on a busy machine (each before or after "
               "the subcommand). `<command> --config FILE`: its fields from a TOML/YAML file or a run.json, flags "
               "override the file; --version: the package's version.")


def parse_command(argv: list[str]):
    """The config a command line (after `bodyschema`, without the logging flags) stands for; a parsing error is
    tyro's message box and exit 2, a config's own check (a ValueError) is raised for the house error."""
    check_sweep_flags(argv)
    argv, file = config_file.split_flag(argv)
    words = commands.words_of(argv)
    if file is None:
        return tyro_marks.cli(commands.tyro_type(words), prog="bodyschema", args=argv, description=DESCRIPTION)
    command = " ".join(["bodyschema", *words])                  # --config FILE: the file's values are defaults
    config_type = config_file.command_type(commands.tyro_type(words), words)
    default = config_file.load_config(file, config_type, command)
    return tyro_marks.cli(config_type, prog=command, args=argv[len(words):], default=default)
