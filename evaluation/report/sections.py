"""The sections of the report: for every benchmark folder under `results` (`results/<name>/` or
`results/<group>/<name>/`, holding run folders `<run-id>/` and `latest` links) the latest run on each robot (a
benchmark without a robot: its latest run), or the run named with `--runs` in its place; a plain folder holding a
`summary.md` is a section too. The files of each run that the report may not use are returned as skipped, with the
reason: empty or truncated, older than the summary.md by more than `stale_after_s`, or with a real path outside the
run folder (a symlink elsewhere: never opened). An incomplete run (runs.is_complete: killed before its last write) is
never a section: it is listed as skipped, and naming it with `--runs` is the house error."""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, field
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.evaluation.core.runs import (
    MODELS_CSV,
    is_benchmark_folder,
    is_complete,
    is_run_folder,
    latest_runs,
    read_run_record,
    run_robot,
)
from bodyschema.evaluation.report.confined import is_inside, resolved
from bodyschema.evaluation.report.pipeline import benchmark_of, order_key

MAX_DEPTH = 2                  # results/<benchmark>/<run> or results/<group>/<benchmark>/<run>
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
OUTSIDE = "outside its run folder (a link elsewhere): not read"
INCOMPLETE = "an incomplete run (killed, or still running): not reported"
_log = logging.getLogger(__name__)


@dataclass
class Section:
    folder_name: str                   # the benchmark folder relative to results, e.g. "adaptation/jupiter"
    folder: Path                       # the run folder (or a plain folder holding a summary.md)
    summary_path: Path
    summary: str                       # the summary.md text
    robot: str | None = None           # the robot the run names (its label), None: none
    benchmark: str | None = None       # the registry key (pipeline.benchmark_of), None: not a registered benchmark
    models: str | None = None          # the models, where the robot has runs of several (`levels · nao_arm · …gpr`)
    plots: list[Path] = field(default_factory=list)
    tables: list[Path] = field(default_factory=list)

    @property
    def name(self) -> str:
        """The section's heading: its folder, and its robot (`reaching · panda`)."""
        return " · ".join(filter(None, (self.folder_name, self.robot, self.models)))


def find_sections(results: Path, stale_after_s: float = 3600.0, runs=()
                  ) -> tuple[list[Section], list[tuple[Path, str]]]:
    """Every readable benchmark section under `results`, in report order, and the (file, reason) pairs skipped;
    `runs`: run folders chosen instead of their benchmark's latest."""
    skipped, sections = [], []
    folders = list(_folders(results, runs=[resolved(r) for r in runs]))
    _check_runs(runs, folders, results)
    for run in _incomplete(results):
        _log.warning("%s: %s", run, INCOMPLETE)
        skipped.append((run, INCOMPLETE))
    for folder in folders:
        summary_path = _summary_file(folder)
        if summary_path is None:
            continue
        if not is_inside(summary_path, folder):
            skipped.append((summary_path, OUTSIDE))
            continue
        try:
            text = summary_path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            skipped.append((summary_path, f"unreadable ({type(e).__name__})"))
            continue
        if not text.strip():
            skipped.append((summary_path, "empty summary"))
            continue
        bench_folder = folder.parent if folder.parent != results and is_benchmark_folder(folder.parent) else folder
        name = bench_folder.relative_to(results).as_posix()
        record = read_run_record(folder)                         # {} for a plain folder or a run older than it
        sections.append(Section(name, folder, summary_path, text, run_robot(folder), benchmark_of(record, name)))
    _name_models(sections)
    owned = [s.folder for s in sections]
    skipped += [(top, "outputs but no summary.md") for top in _unreported(results, owned)]
    for section in sections:
        for path in _owned_files(section.folder, owned):
            reason = (OUTSIDE if not is_inside(path, section.folder)
                      else _skip_reason(path, section.summary_path.stat().st_mtime, stale_after_s))
            if reason:
                skipped.append((path, reason))
            else:
                (section.plots if path.suffix.lower() == ".png" else section.tables).append(path)
    sections.sort(key=lambda s: order_key(s.benchmark, s.folder_name, s.robot))
    return sections, sorted(skipped)


def _folders(results: Path, depth: int = 1, runs=()):
    """Candidate sections: the chosen run on each robot of every benchmark folder, and plain folders (not inside a
    benchmark)."""
    for child in sorted(p for p in results.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))):
        if is_benchmark_folder(child):
            chosen = latest_per_model(child)
            for run in (r for r in runs if r.parent == child.resolve()):      # a named run replaces its own latest
                chosen[(run_robot(run), models_of(run))] = child / run.name
            yield from (chosen[key] for key in sorted(chosen, key=lambda k: (k[0] or "", k[1])))
        else:
            yield child
            if depth < MAX_DEPTH:
                yield from _folders(child, depth + 1, runs)


def latest_per_model(root: Path) -> dict[tuple[str | None, tuple[str, ...]], Path]:
    """The latest run of each robot *and models* under `root`: (robot label, model specs) → run folder. Each robot's
    `latest`/`latest-<robot>` run counts for its models; a newer run with other models no longer hides an older one
    (a pixel levels run replaced the GPR one on the same robot): for those, the newest complete run by its name (the
    UTC start). A run without run.json (older than it) counts only through the links, as before."""
    chosen = {(robot, models_of(run)): run for robot, run in latest_runs(root).items()}
    robots = {robot for robot, _ in chosen}
    for run in sorted((r for r in root.iterdir() if is_run_folder(r) and is_complete(r)), reverse=True):
        robot = run_robot(run)
        if robot in robots and read_run_record(run):
            chosen.setdefault((robot, models_of(run)), run)
    return chosen


def _name_models(sections: list[Section]) -> None:
    """Sections of one benchmark and robot with other models: each heading names its models (registered names, else
    the specs), so both stay apart; a robot's only section keeps its heading (`levels · nao_arm`)."""
    groups: dict[tuple, list[Section]] = {}
    for section in sections:
        groups.setdefault((section.folder_name, section.robot), []).append(section)
    for group in (g for g in groups.values() if len(g) > 1):
        for section in group:
            names = [row.get("name") or row.get("spec") or "" for row in _models_rows(section.folder)]
            section.models = " + ".join(filter(None, names)) or " + ".join(models_of(section.folder)) or "no models"


def _models_rows(run: Path) -> list[dict]:
    path = run / MODELS_CSV
    if not (path.is_file() and is_inside(path, run)):
        return []
    try:
        with open(path, newline="", encoding="utf-8") as f:
            return list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


def models_of(run: Path) -> tuple[str, ...]:
    """The model specs a run used: models.csv's `spec` column (defaults included), else its run.json's `models`
    field as given; () for a benchmark that records none."""
    specs = tuple(row.get("spec") or "" for row in _models_rows(run))
    if any(specs):
        return specs
    given = read_run_record(run).get("fields", {})
    models = given.get("models") if isinstance(given, dict) else None
    return tuple(map(str, models)) if isinstance(models, (list, tuple)) else ()


def _incomplete(results: Path, depth: int = 1) -> list[Path]:
    """The incomplete run folders of every benchmark folder under `results`."""
    found = []
    for child in sorted(p for p in results.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))):
        if is_benchmark_folder(child):
            found += [r for r in sorted(child.iterdir()) if is_run_folder(r) and not is_complete(r)]
        elif depth < MAX_DEPTH:
            found += _incomplete(child, depth + 1)
    return found


def refuse_incomplete(run: Path) -> None:
    """The house error for a run folder named with --runs that was killed (or is still running), whatever it holds
    yet (a run killed early has no summary.md)."""
    if is_run_folder(Path(run)) and not is_complete(Path(run)):
        raise ValueError(must_be("runs", "complete runs", str(run), "It was killed (or is still running) before "
                                 "its last write; rerun the benchmark, or name another run."))


def _check_runs(runs, folders: list[Path], results: Path) -> None:
    """Every run named with --runs is one the report shows: the house error, never a silent fallback to latest."""
    chosen = {resolved(f) for f in folders}
    for run in runs:
        refuse_incomplete(run)
        if resolved(run) not in chosen:
            hint = ("Name one run per benchmark and robot, as results/<benchmark>/<run-id>." if is_inside(run, results)
                    else f"It is outside {results.as_posix()!r}: pass --results with the folder that holds it.")
            raise ValueError(must_be("runs", f"run folders of benchmarks under results {results.as_posix()!r}",
                                     str(run), hint))


def _summary_file(folder: Path) -> Path | None:
    return folder / "summary.md" if (folder / "summary.md").is_file() else None


def _unreported(results: Path, sections: list[Path]) -> list[Path]:
    """Top-level folders holding plots or CSVs but no section: a benchmark that wrote no summary.md."""
    tops = [p for p in results.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))]
    return [t for t in tops if not any(t == s or t in s.parents for s in sections) and _owned_files(t, [])]


def _owned_files(folder: Path, sections: list[Path]) -> list[Path]:
    """PNG and CSV files of `folder` and its subfolders, except those of nested sections; hidden files are skipped."""
    nested = [s for s in sections if s != folder and folder in s.parents]
    files = []
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).parts
        if (path.suffix.lower() in (".png", ".csv") and path.is_file() and not any(p.startswith(".") for p in rel)
                and not any(n in path.parents for n in nested)):
            files.append(path)
    return files


def _skip_reason(path: Path, summary_mtime: float, stale_after_s: float) -> str | None:
    try:
        stat = path.stat()
        with open(path, "rb") as f:
            head = f.read(len(PNG_SIGNATURE))
    except OSError as e:                                              # removed or locked by a running benchmark
        return f"unreadable ({type(e).__name__})"
    if stat.st_size == 0:
        return "empty file"
    if path.suffix.lower() == ".png" and head != PNG_SIGNATURE:
        return "not a PNG (truncated or corrupt)"
    if summary_mtime - stat.st_mtime > stale_after_s:
        return f"stale: {_duration(summary_mtime - stat.st_mtime)} older than its summary.md (an earlier run)"
    return None


def _duration(seconds: float) -> str:
    return f"{seconds / 3600:.1f} h" if seconds >= 3600 else f"{seconds / 60:.0f} min"
