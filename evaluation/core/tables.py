"""The one table writer of the benchmarks: rows (dicts) as CSV and as a Markdown table."""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from pathlib import Path

WALL_COLUMNS = ("wall_s",)     # wall-clock time: the only columns that differ between two runs of one seed


def write_csv(rows: Sequence[Mapping], path: Path) -> Path:
    """Every row as one CSV line; the header is the union of the rows' keys, in first-seen order."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    return path


def markdown_table(table: Sequence[Mapping], columns: Sequence[str], key: str, digits: int = 4) -> str:
    """A Markdown table, one row per value of `key`; a float with `digits` significant digits, as `<value> ± <std>`
    when the row holds `<column>_std`; a count or a name as it is; a missing cell as "–"."""
    lines = [f"| {key} | " + " | ".join(columns) + " |", "|" + "---|" * (len(columns) + 1)]
    for row in table:
        cells = []
        for c in columns:
            if c not in row:
                cells.append("–")
                continue
            std = row.get(f"{c}_std")
            value = f"{row[c]:.{digits}g}" if isinstance(row[c], float) else str(row[c])   # counts, names: as is
            cells.append(f"{value} ± {std:.2g}" if std is not None else value)
        lines.append(f"| {row[key]} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def is_wall_column(name: str) -> bool:
    """A column of wall-clock time (it differs between two runs of the same seed)."""
    return name in WALL_COLUMNS or name.startswith("wall_s") or name.endswith("/wall_s")
