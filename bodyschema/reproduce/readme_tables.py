"""A README table beside its reproduction: the figures of the table marked `<!-- reproduce: <marker> -->` and the
same cells computed from a results CSV, with the difference, and whether it lies within the README's stated ±.

A README cell's figure is its first number ("**0.59°** ± 0.01" → 0.59, ± 0.01; "82.7 %" → 82.7); a cell without
one is skipped.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.reproduce.recipes import Table

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
    """A README cell's figure and its ± (None when absent)."""
    text = cell.replace("*", "").replace("−", "-")
    spread = SPREAD.search(text)
    number = NUMBER.search(SPREAD.sub("", text))
    return (float(number.group()) if number else None), (float(spread.group(1)) if spread else None)


def compare(table: Table, readme: Path, results_csv: Path) -> dict[str, dict[str, Cell]]:
    """README row label → README column → Cell, for the rows and columns the recipe maps."""
    header, rows = readme_table(readme, table.marker)
    with open(results_csv, newline="") as f:
        results = {row[table.key]: row for row in csv.DictReader(f)}
    compared = {}
    for prefix, key in table.rows:
        row = next((r for r in rows if r[0].replace("*", "").startswith(prefix)), None)
        if row is None:
            raise ValueError(must_be(f"the README table {table.marker!r}", f"a row starting {prefix!r}",
                                     [r[0] for r in rows], "Fix the recipe's rows (bodyschema/reproduce/recipes.py)."))
        ours = results.get(key, {})
        cells = {}
        for column in table.columns:
            if column.readme not in header:
                raise ValueError(must_be(f"the README table {table.marker!r}", f"a column {column.readme!r}", header))
            value, spread = figure(row[header.index(column.readme)])
            got = ours.get(column.result)
            cells[column.readme] = Cell(value, spread, float(got) * column.scale if got not in (None, "") else None)
        compared[row[0]] = cells
    return compared


def markdown(compared: dict[str, dict[str, Cell]]) -> str:
    """One row per README row; a cell reads "README → reproduced (Δ)", with ✓/✗ where the README states a ±."""
    columns = list(next(iter(compared.values())))
    lines = ["| row | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for label, cells in compared.items():
        lines.append(f"| {label} | " + " | ".join(_shown(cells[c]) for c in columns) + " |")
    return "\n".join(lines)


def _shown(cell: Cell) -> str:
    if cell.reproduced is None:
        return f"{_num(cell.readme)} → (missing)"
    if cell.readme is None:
        return f"→ {_num(cell.reproduced)}"
    verdict = "" if cell.within is None else (" ✓ within ±" if cell.within else f" ✗ outside ±{cell.spread:g}")
    return f"{_num(cell.readme)} → {_num(cell.reproduced)} ({cell.difference:+.3g}){verdict}"


def _num(value: float | None) -> str:
    return "—" if value is None else f"{value:.3g}"
