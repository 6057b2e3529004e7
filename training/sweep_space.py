"""The search space of `bodyschema sweep KIND`: `--grid name=v1,v2` and `--space name=lo:hi[:log]`, parsed and checked
with the kind's own hyper-parameter class (models/configs.py), then turned into a Ray Tune `param_space`.

Values are read by the field's annotation: an int, a float, true/false, a listed word, `none` where None is allowed,
and a layer list as `64x64` (`x` between widths: a comma separates grid values). Every value is then passed through
the config class itself, so a sweep refuses exactly what `bodyschema train KIND` refuses, before any work.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import types
import typing
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Literal

from bodyschema.errors import must_be
from bodyschema.models.configs import ModelConfig, _expected

# Every trial is a whole fit (seconds to hours): far above a useful sweep (the README's: 6–24 trials), far below one
# that would not end (a 1000×1000 grid: 10⁶ fits). A count like any other of the project: bounded, the bound named.
MAX_TRIALS = 1_000


@dataclass(frozen=True)
class Dimension:
    name: str
    grid: tuple[Any, ...] = ()               # grid values, or () for a random dimension
    low: float | None = None                 # random dimension: bounds, inclusive (ints: both ends drawn)
    high: float | None = None
    log: bool = False                        # drawn uniformly in log space


@dataclass(frozen=True)
class SearchSpace:
    config_class: type[ModelConfig]
    dimensions: tuple[Dimension, ...]
    samples: int                             # Tune's num_samples: draws per grid point (1 for a pure grid)

    @property
    def trials(self) -> int:
        return self.samples * math.prod(len(d.grid) for d in self.dimensions if d.grid)

    def first(self) -> dict[str, Any]:
        """The first configuration (first grid values, random dimensions at their low end): the cost probe's."""
        return {d.name: d.grid[0] if d.grid else d.low for d in self.dimensions}

    def points(self) -> Iterator[dict[str, Any]]:
        """Every grid point, each random dimension at its high end (the largest network it may draw): the points
        whose fits the memory guard checks."""
        high = {d.name: (int(d.high) if _hint(self.config_class, d.name) is int else d.high)
                for d in self.dimensions if not d.grid}
        grids = [d for d in self.dimensions if d.grid]
        for values in itertools.product(*(d.grid for d in grids)):
            yield {**{d.name: v for d, v in zip(grids, values)}, **high}

    def describe(self) -> dict[str, str]:
        """name → "v1, v2" or "lo..hi (log)": the parent run's params."""
        return {d.name: ", ".join(map(str, d.grid)) if d.grid else f"{d.low}..{d.high}" + (" (log)" if d.log else "")
                for d in self.dimensions}

    def param_space(self) -> dict[str, Any]:
        from ray import tune

        space = {}
        for d in self.dimensions:
            if d.grid:
                space[d.name] = tune.grid_search(list(d.grid))
            elif _hint(self.config_class, d.name) is int:
                draw = tune.lograndint if d.log else tune.randint
                space[d.name] = draw(int(d.low), int(d.high) + 1)          # randint's upper end is exclusive
            else:
                space[d.name] = (tune.loguniform if d.log else tune.uniform)(d.low, d.high)
        return space


def parse_space(config_class: type[ModelConfig], kind: str, grid: tuple[str, ...], space: tuple[str, ...],
                random: int) -> SearchSpace:
    """The checked search space; ValueError (the house line, every problem listed) on bad input."""
    problems: list[str] = []
    dims: list[Dimension] = []
    for items, parse in ((grid, _grid_dimension), (space, _random_dimension)):
        for item in items:
            try:
                dims.append(parse(config_class, kind, item))
            except ValueError as error:
                problems.append(str(error))
    names = [d.name for d in dims]
    for name in sorted({n for n in names if names.count(n) > 1}):
        problems.append(must_be(f"hyper-parameter {name}", "named once across --grid and --space", names.count(name),
                                "Give all its values in one --grid entry."))
    if random < 0:
        problems.append(must_be("--random", "a count ≥ 0 of random draws", random))
    elif space and random < 1:
        problems.append(must_be("--random", "≥ 1 when --space is given", random, "Say how many draws: --random N."))
    if random > 0 and not space:
        problems.append(must_be("--space", "at least one name=lo:hi[:log] with --random", "nothing",
                                "Name what to draw, e.g. --space lr=1e-4:1e-2:log."))
    if not dims and not problems:
        problems.append(must_be("the search space", "a non-empty --grid name=v1,v2 or --random N --space "
                                "name=lo:hi[:log]", "nothing", f"See `bodyschema train {kind} --help` for the names."))
    result = SearchSpace(config_class, tuple(dims), max(random, 1))
    if not problems and result.trials > MAX_TRIALS:
        problems.append(must_be("the number of trials (grid points × --random draws)", f"at most {MAX_TRIALS:,}",
                                result.trials, "Every trial is a whole fit: sweep in stages, a coarse grid first, "
                                "then a finer one around its best (or draw --random N over --space)."))
    if problems:
        raise ValueError("\n".join(problems))
    return result


def tunable(config_class: type[ModelConfig]) -> list[str]:
    return [f.name for f in dataclasses.fields(config_class) if f.name not in config_class.not_on_cli]


def _grid_dimension(config_class, kind: str, item: str) -> Dimension:
    name, texts = _split(config_class, kind, "--grid", item, "name=v1,v2")
    values = tuple(_parse(config_class, name, t.strip(), f"--grid {name}") for t in texts.split(",") if t.strip())
    if not values:
        raise ValueError(must_be(f"--grid {name}", "at least one value", item, f"Write {name}=v1,v2."))
    repeated = sorted({_text(v) for v in values if values.count(v) > 1})
    if repeated:                                                           # a typo for another value, most likely
        raise ValueError(must_be(f"--grid {name}", "distinct values", item,
                                 f"{', '.join(repeated)} is given twice: a repeated value is one trial, not two."))
    return Dimension(name, grid=values)


def _text(value: Any) -> str:
    return "x".join(map(str, value)) if isinstance(value, tuple) else str(value)


def _random_dimension(config_class, kind: str, item: str) -> Dimension:
    name, bounds = _split(config_class, kind, "--space", item, "name=lo:hi[:log]")
    hint, flag, parts = _hint(config_class, name), f"--space {name}", bounds.split(":")
    if hint not in (int, float) or len(parts) not in (2, 3) or parts[2:] not in ([], ["log"]):
        raise ValueError(must_be(flag, "lo:hi or lo:hi:log over an int or float hyper-parameter", item,
                                 "Sweep words, lists and optional values with --grid."))
    low, high = (_parse(config_class, name, p, flag) for p in parts[:2])
    log = parts[2:] == ["log"]
    if not low < high or (log and low <= 0):
        raise ValueError(must_be(flag, "lo < hi (and lo > 0 on a log scale)", bounds))
    return Dimension(name, low=low, high=high, log=log)


def _split(config_class, kind: str, flag: str, item: str, form: str) -> tuple[str, str]:
    name, sep, rest = item.partition("=")
    name = name.strip().lstrip("-").replace("-", "_")
    valid = tunable(config_class)
    if not sep:
        raise ValueError(must_be(flag, form, item))
    if name not in valid:
        raise ValueError(must_be(f"{flag} name {name!r}", f"a hyper-parameter of {kind}: one of {valid}", item,
                                 f"See `bodyschema train {kind} --help`."))
    return name, rest


def _hint(config_class, name: str):
    return typing.get_type_hints(config_class)[name]


def _parse(config_class, name: str, text: str, flag: str) -> Any:
    """`text` as the field's type, then checked by the config class itself (its ranges, COUNTS ≥ 1)."""
    hint = _hint(config_class, name)
    try:
        value = _read(text, hint)
        config_class(**{name: value})
    except (ValueError, TypeError):
        raise ValueError(must_be(flag, _expected(name, hint) + ("" if typing.get_origin(hint) is not tuple else
                                                          ", widths joined by x (64x64)"), text)) from None
    return value


def _read(text: str, hint) -> Any:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if text.lower() == "none" and type(None) in args:
            return None
        for arg in (a for a in args if a is not type(None)):
            try:
                return _read(text, arg)
            except ValueError:
                pass
        raise ValueError(text)
    if origin is Literal:
        if text not in args:
            raise ValueError(text)
        return text
    if hint is bool:
        if text.lower() not in ("true", "false"):
            raise ValueError(text)
        return text.lower() == "true"
    if origin is tuple:
        return tuple(int(p) for p in text.split("x"))
    if hint in (int, float, str):
        return hint(text)
    raise ValueError(text)

