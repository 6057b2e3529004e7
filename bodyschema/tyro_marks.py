"""The CLI's bridge to tyro: the marks of bodyschema/cli_marks.py as tyro's, and a config's own error as ours.

Both go through tyro's public constructor registry (`tyro.constructors`): one struct rule asks tyro's own rule for a
dataclass's fields (their defaults and their help, the comment after each field, read from the class's source), then
gives each field tyro's markers for ours and wraps the class so a `ValueError` of its `__post_init__` leaves tyro as
`ConfigRejected` (shown as the house line by the CLI's error boundary) instead of tyro's error box. The configs stay
plain: the objects tyro builds are the config classes themselves.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import typing
from typing import Annotated

import tyro
from tyro.constructors import ConstructorRegistry, StructConstructorSpec, StructTypeInfo

from bodyschema.cli_marks import Flag, Flat, Positional, Ungrouped

MARKS = (Positional, Flat, Ungrouped, Flag)
REGISTRY = ConstructorRegistry()
_asking_tyro: set[type] = set()   # the classes whose spec tyro's own rule is building for `_plain_config`


class ConfigRejected(Exception):
    """A config's own check (`__post_init__`) refused the parsed values. Not a ValueError: tyro would catch it and
    box it; `error` is the config's ValueError, raised again by `cli` once outside tyro."""

    def __init__(self, error: ValueError):
        super().__init__(str(error))
        self.error = error


def cli(kind, **kwargs):
    """`tyro.cli` with our marks understood; a config's own ValueError is raised as it is, outside tyro's box."""
    try:
        return tyro.cli(kind, registry=REGISTRY, **kwargs)
    except ConfigRejected as rejected:
        raise rejected.error from None


@REGISTRY.struct_rule
def _plain_config(info: StructTypeInfo) -> StructConstructorSpec | None:
    if not dataclasses.is_dataclass(info.type) or info.type in _asking_tyro:
        return None
    _asking_tyro.add(info.type)         # tyro asks every rule again, this one first: it must pass this time
    try:
        spec = ConstructorRegistry.get_struct_spec(info)
    finally:
        _asking_tyro.discard(info.type)
    if not isinstance(spec, StructConstructorSpec):
        return spec
    fields = tuple(dataclasses.replace(f, type=as_tyro(f.type)) for f in spec.fields)
    return StructConstructorSpec(instantiate=_rejecting(spec.instantiate), fields=fields)


def _rejecting(instantiate):
    @functools.wraps(instantiate)
    def build(*args, **kwargs):
        try:
            return instantiate(*args, **kwargs)
        except ValueError as error:
            raise ConfigRejected(error) from error
    build.__doc__ = _own_doc(instantiate)     # tyro describes a command or group by its docstring
    return build


def _own_doc(cls) -> str | None:
    """The class's docstring; None for the one `dataclass` writes in its place (its signature), as tyro skips it."""
    generated = cls.__name__ + str(inspect.signature(cls)).replace(" -> None", "")
    return None if cls.__doc__ == generated else cls.__doc__


def as_tyro(hint):
    """A field's type with tyro's markers in place of ours (unchanged without ours)."""
    if typing.get_origin(hint) is not Annotated:
        return hint
    base, *metadata = typing.get_args(hint)
    ours = [m for m in metadata if isinstance(m, MARKS)]
    if not ours:
        return hint
    theirs = [t for m in ours for t in _translated(m)]
    return Annotated[(base, *[m for m in metadata if not isinstance(m, MARKS)], *theirs)]


def _translated(mark) -> tuple:
    if isinstance(mark, Positional):
        return (tyro.conf.Positional, *([tyro.conf.arg(metavar=mark.metavar)] if mark.metavar else []))
    if isinstance(mark, Flat):
        return (tyro.conf.OmitArgPrefixes,)
    if isinstance(mark, Ungrouped):
        return (tyro.conf.arg(name=""),)
    details = {"help": mark.help, "aliases": mark.aliases or None, "help_behavior_hint": mark.default_hint}
    return (*([tyro.conf.UseAppendAction] if mark.append else []),
            tyro.conf.arg(**{k: v for k, v in details.items() if v is not None}))
