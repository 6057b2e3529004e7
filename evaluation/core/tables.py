"""The one table writer of the benchmarks: rows (dicts) as CSV and as a Markdown table, and the one escape of
user text (names, paths, specs) put into Markdown."""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

WALL_COLUMNS = ("wall_s",)     # wall-clock time: the only columns that differ between two runs of one seed
MARKUP = re.compile(r"([\\`|\[\]<>&])")   # what can start a link, an image, code, raw HTML or a table cell
LINE_BREAKS = re.compile(r"[\x00-\x1f\x7f]+")  # a newline in a name would end the table row (or the paragraph)


def escape_markdown(text: object) -> str:
    """`text` shown as itself in Markdown: a name like `[x](http://evil)` or `<img src=…>` stays text, on GitHub
    and in the report's HTML alike (CommonMark backslash escapes); control characters become one space."""
    return MARKUP.sub(r"\\\1", LINE_BREAKS.sub(" ", str(text)))


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
    when the row holds `<column>_std`; a count or a name as it is (escaped); a missing cell as "–"."""
    lines = ["| " + " | ".join(map(escape_markdown, (key, *columns))) + " |", "|" + "---|" * (len(columns) + 1)]
    for row in table:
        cells = []
        for c in columns:
            if c not in row:
                cells.append("–")
                continue
            std = row.get(f"{c}_std")
            value = f"{row[c]:.{digits}g}" if isinstance(row[c], float) else escape_markdown(row[c])  # counts, names
            cells.append(f"{value} ± {std:.2g}" if std is not None else value)
        lines.append(f"| {escape_markdown(row[key])} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def is_wall_column(name: str) -> bool:
    """A column of wall-clock time (it differs between two runs of the same seed)."""
    return name in WALL_COLUMNS or name.startswith("wall_s") or name.endswith("/wall_s")
