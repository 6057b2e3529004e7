"""`summary.md` in a training run's folder: its model cards, the versions it registered and its plots, the
"models" section `bodyschema report` shows for each trained model (evaluation/report/trained.py).

Written last, after registration, beside a temporary file and renamed into place: a run killed before holds none
(the report then leaves it out), a run finished holds a whole one. Only the process that owns the run folder
(runs.claim) writes it.
"""

from __future__ import annotations

import os
from pathlib import Path

SUMMARY = "summary.md"


def write(run_dir: Path, cards: list[str], registered: list, plots: dict[str, Path]) -> Path:
    """The run's summary.md: each model card (headings one level down), what became which version, the plots."""
    lines = []
    for card in cards:
        lines += [card.rstrip(), ""]
    lines += [f"Registered: {r.name} v{r.version}{' (now @champion)' if r.champion else ''}" for r in registered]
    lines += [""] + [f"![{name}]({path.relative_to(run_dir).as_posix()})" for name, path in plots.items()
                     if path.is_relative_to(run_dir)]
    path = run_dir / SUMMARY
    partial = path.with_name(f".{SUMMARY}.{os.getpid()}")
    partial.write_text("\n".join(lines).rstrip() + "\n")
    partial.replace(path)
    return path
