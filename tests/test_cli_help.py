"""A flag's --help is its field's whole comment. tyro reads a field's help from the comment on its line or the comment
lines above it; a trailing comment continued on the lines below is cut there (`robot camera --add` said "for the
joints the", `evaluate levels --floor` lost its second line), or joins the next field's help."""

from __future__ import annotations

import dataclasses
import inspect
import re
import typing

import pytest

from bodyschema import commands
from bodyschema.aif.perception_config import FlowSettings
from bodyschema.cli import main
from bodyschema.models.configs import GPRConfig

FIELD = re.compile(r"^(\s+)\w+: [^#]+#")          # a dataclass field with a trailing comment


def config_classes() -> set[type]:
    """Every dataclass tyro parses: each command's config and the dataclasses nested in it."""
    seen, todo = set(), [command.config() for command in commands.table()]
    while todo:
        cls = todo.pop()
        if typing.get_origin(cls) is not None:                   # TrainConfig[GPRConfig]: the class and its argument
            todo += [typing.get_origin(cls), *typing.get_args(cls)]
        elif isinstance(cls, type) and dataclasses.is_dataclass(cls) and cls not in seen:
            seen.add(cls)
            hints = typing.get_type_hints(cls, include_extras=True)
            todo += [arg for hint in hints.values() for arg in (hint, *typing.get_args(hint))]
    return seen


def continued_comments(cls: type) -> list[str]:
    """The fields of `cls` whose trailing comment goes on below them, on comment-only lines indented deeper."""
    lines = inspect.getsource(cls).splitlines()
    return [line.split(":")[0].strip() for line, below in zip(lines, lines[1:])
            if (field := FIELD.match(line)) and below.lstrip().startswith("#")
            and len(below) - len(below.lstrip()) > len(field.group(1))]


@dataclasses.dataclass
class Continued:
    cut: int = 1                   # what --help shows
                                   # what it cut
    whole: int = 2                 # one line


def test_a_trailing_comment_continued_below_is_found():
    assert continued_comments(Continued) == ["cut"]


def test_no_option_continues_its_trailing_comment_below():
    classes = config_classes()
    roots = {typing.get_origin(c) or c for c in (command.config() for command in commands.table())}
    assert roots < classes and FlowSettings in classes and GPRConfig in classes             # nested ones too
    found = {cls.__qualname__: fields for cls in classes if (fields := continued_comments(cls))}
    assert found == {}, "put these comments above their fields (tyro cuts the lines below from --help)"


@pytest.mark.parametrize("command, words", [
    (["robot", "camera"], "it may be a close-up that loses the ee in some poses"),
    (["evaluate", "levels"], "cheap for every model"),
])
def test_the_help_holds_the_whole_comment(capsys, command, words):
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    assert words in " ".join(capsys.readouterr().out.replace("│", " ").split())
