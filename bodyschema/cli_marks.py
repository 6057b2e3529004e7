"""How a config field shows on the command line, said without the CLI library: marks for `typing.Annotated`.

    source: Annotated[Path, Positional("SOURCE")]              # bodyschema import SOURCE ...
    model: Annotated[M, Flat()]                                # --noise-floor, not --model.noise-floor
    flow: Annotated[FlowSettings, Ungrouped()] = FlowSettings()  # --perception.dt, not --perception.flow.dt
    models: Annotated[tuple[str, ...], Flag(append=True, aliases=("--model",), help="...")] = ()

The configs below the CLI (datagen, training, aif, evaluation) are plain frozen dataclasses: a library user builds
them by hand, a config file builds them by name (bodyschema/config_file.py) and the CLI builds them from flags. The
CLI alone knows the CLI library (tyro): bodyschema/tyro_marks.py turns these marks into tyro's when it parses. A
field's help line is still the comment after it (or `Flag(help=...)`).

A leaf, like bodyschema/errors.py: it imports only the standard library, so any config module may import it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Positional:
    """A positional argument (no `--name`), shown in the usage line as `metavar` (None: the field's name)."""

    metavar: str | None = None


@dataclass(frozen=True)
class Flat:
    """A nested config whose flags carry no prefix at all: `--noise-floor`, not `--model.noise-floor`."""


@dataclass(frozen=True)
class Ungrouped:
    """A nested config that adds no prefix of its own: its flags keep its parent's (`--perception.dt`, not
    `--perception.flow.dt`), so a group of settings can move into a nested config without a flag changing."""


@dataclass(frozen=True)
class Flag:
    """A flag's details beyond its name, type, default and comment."""

    help: str | None = None           # instead of the comment after the field (a help line built in code)
    aliases: tuple[str, ...] = ()     # other spellings of the flag, e.g. ("--model",) for --models
    append: bool = False              # a tuple given one item per flag: `--model A --model B`
    default_hint: str | None = None   # instead of "(default: ...)", for a default the CLI itself changes
