"""The flat flags of `evaluate` (issue 13: --trials everywhere, no nested prefixes) parse."""

from __future__ import annotations

import pytest

from bodyschema.cli import parse_command


@pytest.mark.parametrize("args, field, value", [
    (["evaluate", "reaching", "--trials", "7"], "trials", 7),
    (["evaluate", "loop-robustness", "--trials", "5", "--robot", "panda"], "robot", "panda"),
    (["evaluate", "robustness", "--trials", "9", "--level", "1"], "trials", 9),
    (["evaluate", "adaptation", "marker-shift", "--trials", "3"], "trials", 3),
    (["evaluate", "adaptation", "jupiter", "--trials", "2", "--no-progress"], "progress", False),
    (["evaluate", "self-recognition", "--trials", "12"], "trials", 12),
])
def test_the_flat_flags_parse(args, field, value):
    assert getattr(parse_command(args), field) == value
