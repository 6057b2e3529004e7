"""A README table beside its reproduction: the figures of the table marked `<!-- reproduce: <marker> -->` and the
same cells computed from a results CSV, with the difference, and whether it lies within the README's stated ±.

A README cell's figures: its parts ("0.003 / 9.8 mm" → two, "72 % (91 % within 1 px)" → two), each part's figure
its first number ("**0.59°** ± 0.01" → 0.59, ± 0.01; "82.7 %" → 82.7). A part without a figure is shown, not compared.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.reproduce.recipes import Part, Row, Table

PARTS = re.compile(r"\s+/\s+|\s+\(")      # "a / b", "a (b)": a cell of several figures
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
SPREAD = re.compile(r"±\s*(\d+(?:\.\d+)?)")


@dataclass(frozen=True)
class Cell:
    readme: float | None
    spread: float | None             # the README's "± s", when the cell states one
    reproduced: float | None

    @property
    def difference(self) -> float | None:
        if self.readme is None or self.reproduced is None:
            return None
        return self.reproduced - self.readme

    @property
    def within(self) -> bool | None:
        if self.spread is None or self.difference is None:
            return None
        return abs(self.difference) <= self.spread


def readme_table(readme: Path, marker: str) -> tuple[list[str], list[list[str]]]:
    """The header and rows (cells stripped) of the first table after `<!-- reproduce: marker -->`."""
    lines = readme.read_text(encoding="utf-8").splitlines()
    tag = f"<!-- reproduce: {marker} -->"
    if tag not in (line.strip() for line in lines):
        raise ValueError(must_be(f"{readme.name}", f"a table marked {tag}", "no such marker",
                                 "Put the marker on the line above the table the recipe reproduces."))
    start = next(i for i, line in enumerate(lines) if line.strip() == tag)
    table = []
    for line in lines[start + 1:]:
        if line.startswith("|"):
            table.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        elif table:
            break
    if len(table) < 3:
        raise ValueError(must_be(f"the table under {tag}", "a header, a separator and rows", f"{len(table)} lines"))
    return table[0], table[2:]


def figure(cell: str) -> tuple[float | None, float | None]:
    """A README cell's (or part's) figure and its ± (None when absent)."""
    text = cell.replace("*", "").replace("−", "-")
    spread = SPREAD.search(text)
    number = NUMBER.search(SPREAD.sub("", text))
    return (float(number.group()) if number else None), (float(spread.group(1)) if spread else None)


def figures(cell: str, n: int) -> list[tuple[float | None, float | None]]:
    """The figures of a cell's first `n` parts; (None, None) for a part the cell does not have."""
    parts = PARTS.split(cell.strip())
    return [figure(parts[i]) if i < len(parts) else (None, None) for i in range(n)]


def readme_row(table: Table, rows: list[list[str]], row: Row) -> list[str]:
    """The README row whose first cell is `row.readme`, else the first that starts with it."""
    firsts = [r[0].replace("*", "") for r in rows]
    found = firsts.index(row.readme) if row.readme in firsts else next(
        (i for i, first in enumerate(firsts) if first.startswith(row.readme)), None)
    if found is None:
        raise ValueError(must_be(f"the README table {table.marker!r}", f"a row starting {row.readme!r}", firsts,
                                 "Fix the recipe's rows (bodyschema/reproduce/recipes.py)."))
    return rows[found]


def labels(table: Table) -> list[str]:
    """The compared cells' names: a column's header, numbered "(k)" when its cells hold several figures."""
    return [c.readme if len(c.parts) == 1 else f"{c.readme} ({k})" for c in table.columns
            for k in range(1, len(c.parts) + 1)]


def part_location(table: Table, row: Row, part: Part) -> tuple[str, str, str, str]:
    """(step, csv, key column(s), key) of the CSV value a part of `row` reads."""
    return (row.step or table.step, part.csv or table.csv, part.key or table.key, part.row.replace("{}", row.key))


def compare(table: Table, readme: Path, products: Mapping[str, str]) -> dict[str, dict[str, Cell]]:
    """README row label → compared cell (`labels`) → Cell; `products` maps each step to its run folder."""
    header, rows = readme_table(readme, table.marker)
    missing = [c.readme for c in table.columns if c.readme not in header]
    if missing:
        raise ValueError(must_be(f"the README table {table.marker!r}", f"columns {missing}", header))
    read = _reader(products)
    compared = {}
    for row in table.rows:
        cells = readme_row(table, rows, row)
        values = [Cell(value, spread, read(part, *part_location(table, row, part)))
                  for column in table.columns
                  for part, (value, spread) in zip(column.parts, figures(cells[header.index(column.readme)],
                                                                         len(column.parts)))]
        compared[cells[0]] = dict(zip(labels(table), values))
    return compared


def _reader(products: Mapping[str, str]):
    """read(part, step, csv, key column(s), key): the part's value in the README's unit, None where the results
    have none; each CSV is read once."""
    loaded: dict[tuple[str, str, str], dict[str, dict]] = {}

    def read(part: Part, step: str, name: str, key: str, wanted: str) -> float | None:
        if (step, name, key) not in loaded:
            loaded[step, name, key] = _results(Path(products[step]) / name, key)
        got = loaded[step, name, key].get(wanted, {}).get(part.result)
        return float(got) * part.scale if got not in (None, "") else None
    return read


def _results(path: Path, key: str) -> dict[str, dict]:
    """A results CSV's rows by their key: one column's value, or several columns' joined by ","."""
    with open(path, newline="") as f:
        return {",".join(r[k] for k in key.split(",")): r for r in csv.DictReader(f)}


def markdown(compared: dict[str, dict[str, Cell]]) -> str:
    """One row per README row; a cell reads "README → reproduced (Δ)", with ✓/✗ where the README states a ±."""
    columns = list(next(iter(compared.values())))
    lines = ["| row | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for label, cells in compared.items():
        lines.append(f"| {label} | " + " | ".join(_shown(cells[c]) for c in columns) + " |")
    return "\n".join(lines)


def _shown(cell: Cell) -> str:
    if cell.reproduced is None and cell.readme is None:
        return "—"
    if cell.reproduced is None:
        return f"{_num(cell.readme)} → (missing)"
    if cell.readme is None:
        return f"→ {_num(cell.reproduced)}"
    verdict = "" if cell.within is None else (" ✓ within ±" if cell.within else f" ✗ outside ±{cell.spread:g}")
    return f"{_num(cell.readme)} → {_num(cell.reproduced)} ({cell.difference:+.3g}){verdict}"


def _num(value: float | None) -> str:
    return "—" if value is None else f"{value:.3g}"
