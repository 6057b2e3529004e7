"""The "trained" sections: each model `bodyschema train` fitted, from the summary.md it writes in its run folder
(training/run_summary.py: model cards, registered versions, plots) under train's --run-root (`runs` by default).
The latest run of each robot, kind and modality; a run folder without summary.md (killed, or older than this
section) is left out. Files are read only inside their run folder, as for the benchmarks' sections."""

from __future__ import annotations

import json
import re
from pathlib import Path

from bodyschema.evaluation.report.confined import is_inside
from bodyschema.evaluation.report.sections import Section
from bodyschema.training.run_summary import SUMMARY

HELD_OUT = re.compile(r"^- (val_rmse|val_mean_error): (\S+(?: .+)?)$", re.M)     # the score and its unit


def trained_sections(root: Path | None) -> list[Section]:
    """One section per trained robot × kind × modality under `root` (its latest run); [] when there is none."""
    if root is None or not Path(root).is_dir():
        return []
    latest: dict[tuple[str, str], Section] = {}
    for run in sorted(p for p in Path(root).iterdir() if p.is_dir()):
        summary = run / SUMMARY
        if not (summary.is_file() and is_inside(summary, run)):
            continue
        robot, what = _robot(run), run.name.rsplit("-", 1)[0]              # <kind>-<modality>-<hash>
        section = Section("trained", run, summary, summary.read_text(encoding="utf-8"), robot, "trained", what,
                          plots=sorted(p for p in (run / "plots").glob("*.png") if is_inside(p, run)))
        key = (robot or "", what)
        if key not in latest or summary.stat().st_mtime > latest[key].summary_path.stat().st_mtime:
            latest[key] = section
    return list(latest.values())


def held_out(section: Section) -> str:
    """The headline of a trained model: its held-out scores as its card states them."""
    found = HELD_OUT.findall(section.summary)
    return ", ".join(f"{name} {value}" for name, value in found) or "no held-out score in its model card"


def _robot(run: Path) -> str | None:
    """The robot a saved model names (model/meta.json, or the first member's of a multimodal run)."""
    for meta in sorted(run.glob("model*/meta.json")):
        if is_inside(meta, run):
            try:
                return str(json.loads(meta.read_text())["body"]["robot"])
            except (OSError, ValueError, KeyError, TypeError):
                return None
    return None
