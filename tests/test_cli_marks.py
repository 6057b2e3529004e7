"""Plain configs below the CLI: no module outside bodyschema/ imports tyro; their CLI marks (bodyschema/cli_marks.py)
become tyro's in bodyschema/tyro_marks.py; a library call, a config file and the CLI build the same objects of the
plain classes; the command table (bodyschema/commands.py) is what the CLI offers."""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import pytest

from bodyschema import commands, tyro_marks
from bodyschema.cli import main, parse_command
from bodyschema.cli_marks import Flag, Positional, Ungrouped
from tests.import_graph import package_modules


def _imports_tyro(path: Path) -> list[int]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [node.lineno for node in ast.walk(tree)
            if (isinstance(node, ast.Import) and any(a.name.split(".")[0] == "tyro" for a in node.names))
            or (isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "tyro")]


def test_no_module_outside_bodyschema_imports_tyro():
    cli_folder = Path(__file__).resolve().parents[1] / "bodyschema"
    outside = {name: path for name, path in package_modules().items() if not path.resolve().is_relative_to(cli_folder)}
    assert len(outside) > 50, "the walk sees the stages' modules"
    found = {name: lines for name, path in outside.items() if (lines := _imports_tyro(path))}
    assert not found, f"tyro imported outside bodyschema/ (module: lines): {found}"


@dataclass(frozen=True)
class Inner:
    dt: float = 1.0  # the step


@dataclass(frozen=True)
class Marked:
    """A config with every mark."""

    source: Annotated[str, Positional("SOURCE")]  # where from
    specs: Annotated[tuple[str, ...], Flag(append=True, aliases=("--spec",), help="one spec")] = ()
    inner: Annotated[Inner, Ungrouped()] = Inner()
    n: int = 1  # how many

    def __post_init__(self):
        if self.n < 1:
            raise ValueError(f"n must be at least 1. Got {self.n}.")


def test_the_marks_become_tyros():
    config = tyro_marks.cli(Marked, args=["here", "--spec", "a", "--spec", "b", "--dt", "2", "--n", "3"])   # no inner.
    assert config == Marked("here", ("a", "b"), Inner(2.0), 3)
    assert type(config) is Marked and type(config.inner) is Inner, "the plain classes, no CLI subclass"


def test_help_keeps_the_field_comments_and_the_metavar(capsys):
    with pytest.raises(SystemExit):
        tyro_marks.cli(Marked, args=["--help"], prog="marked")
    text = capsys.readouterr().out
    assert "SOURCE" in text and "where from" in text and "how many" in text and "the step" in text
    assert "one spec" in text and "A config with every mark." in text


def test_a_configs_own_check_leaves_tyro_as_its_value_error():
    with pytest.raises(ValueError, match=r"^n must be at least 1\. Got 0\.$"):
        tyro_marks.cli(Marked, args=["here", "--n", "0"])


def test_a_library_call_a_config_file_and_the_cli_build_the_same_config(tmp_path):
    from bodyschema.datagen.exchange.importers.config import ImportConfig

    by_hand = ImportConfig(source=Path("rec"), out=Path("o.zarr"), angles="deg", robot="nao_arm")
    file = tmp_path / "import.json"
    file.write_text(json.dumps({"source": "rec", "out": "o.zarr", "angles": "deg", "robot": "nao_arm"}))
    assert parse_command(["import", "rec", "--out", "o.zarr", "--angles", "deg", "--robot", "nao_arm"]) == by_hand
    assert parse_command(["import", "--config", str(file)]) == by_hand
    assert type(parse_command(["import", "--config", str(file)])) is ImportConfig


def test_the_table_names_each_command_once_and_every_group():
    table = commands.table()
    words = [c.words for c in table]
    assert len(set(words)) == len(words)
    assert ("train", "gpr") in words and ("evaluate", "adaptation", "jupiter") in words
    groups = {w[:i] for w in words for i in range(1, len(w))}
    assert groups <= set(commands.GROUPS), f"groups without help: {groups - set(commands.GROUPS)}"
    assert {w for w in words if commands.find(w).mlflow} >= {("train", "gpr"), ("registry", "list"), ("demo",)}


@pytest.mark.parametrize("words", [["registry", "promote"], ["export", "onnx"], ["robot", "init"]], ids=" ".join)
def test_every_command_of_a_group_is_in_its_help(words, capsys):
    with pytest.raises(SystemExit):
        main([words[0], "--help"])
    assert words[1] in capsys.readouterr().out


def test_a_commands_positional_argument_is_not_a_command_word(tmp_path):
    """`sweep mdn`: mdn is the kind (also `train mdn`'s word); with --config FILE it stays the kind."""
    assert commands.words_of(["sweep", "mdn", "--data", "d.zarr"]) == ["sweep"]
    assert commands.words_of(["train", "mdn", "--data", "d.zarr"]) == ["train", "mdn"]
    file = tmp_path / "sweep.json"
    file.write_text(json.dumps({"data": "d.zarr"}))
    config = parse_command(["sweep", "mdn", "--config", str(file)])
    assert (config.kind, config.data) == ("mdn", Path("d.zarr"))
