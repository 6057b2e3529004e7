"""The flags of `evaluate` that changed (issue 13) exit 2 with the house error naming the new flag; the new flat
flags parse."""

from __future__ import annotations

import pytest
import tyro

from bodyschema.cli import COMMANDS, RENAMED_FLAGS, main

FLATTENED_CASES = [(["evaluate", "robustness"], "--levels.trials", "--trials"),
                   (["evaluate", "robustness"], "--levels.no-mlflow", "--no-mlflow"),
                   (["evaluate", "loop-robustness"], "--reaching.robot", "--robot")]


@pytest.mark.parametrize("words, old", list(RENAMED_FLAGS), ids=lambda x: " ".join(x) if isinstance(x, tuple) else x)
def test_every_renamed_flag_names_its_new_spelling(words, old, capsys):
    assert main([*words, old, "3"]) == 2
    err = capsys.readouterr().err
    new = RENAMED_FLAGS[(words, old)]
    assert f"flag {old} must be" in err and "Got" in err
    assert (f"spelled {new}" in err) if new else "absent from" in err


@pytest.mark.parametrize("words, old, new", FLATTENED_CASES, ids=lambda x: x if isinstance(x, str) else "")
def test_nested_prefixes_are_flattened(words, old, new, capsys):
    assert main([*words, f"{old}=1" if "no-" not in old else old]) == 2
    assert f"spelled {new}" in capsys.readouterr().err


@pytest.mark.parametrize("args, field, value", [
    (["evaluate", "reaching", "--trials", "7"], "trials", 7),
    (["evaluate", "loop-robustness", "--trials", "5", "--robot", "panda"], "robot", "panda"),
    (["evaluate", "robustness", "--trials", "9", "--level", "1"], "trials", 9),
    (["evaluate", "adaptation", "marker-shift", "--trials", "3"], "trials", 3),
    (["evaluate", "adaptation", "jupiter", "--trials", "2", "--no-progress"], "progress", False),
    (["evaluate", "self-recognition", "--trials", "12"], "trials", 12),
])
def test_the_flat_flags_parse(args, field, value):
    assert getattr(tyro.cli(COMMANDS, args=args), field) == value
