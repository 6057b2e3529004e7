"""`bodyschema report`: one Markdown page and one self-contained HTML page gathering every benchmark's summary.md,
plots (PNG) and tables (CSV) found under `results/` — levels, robustness, reaching, adaptation, self-recognition, …

The page opens with its summary: one line per section, linked to it, with the benchmark's key figure
(headline.py). A section is the latest run of a benchmark on one robot (sections.py: which runs, which of their files
are skipped and listed at the end), in pipeline order (pipeline.py); every table header reads as words with units
(headers.py). Under each section's summary the models the run used (models.csv: spec, registered name, version, source
run, weights digest). A summary.md shows only images of its own run folder; its other image links are dropped with
a note, never read (confined.py). Every name taken from the file system or a models.csv is escaped
(`escape_markdown`). The HTML embeds images as base64
and needs no network; `markdown_to_html` (markdown-it-py, tables enabled) converts what summary.md files hold
(headings, paragraphs, pipe tables, lists, code, links, images). Both pages are written to temporary files
and renamed only once complete, so a failure never leaves a half-written report.
"""

from __future__ import annotations

import csv
import os
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote, unquote

from bodyschema.errors import must_be
from bodyschema.evaluation.core.runs import MODELS_CSV
from bodyschema.evaluation.core.tables import escape_markdown, markdown_table
from bodyschema.evaluation.report.confined import is_inside, resolved
from bodyschema.evaluation.report.headers import readable_tables
from bodyschema.evaluation.report.headline import headline
from bodyschema.evaluation.report.markdown_html import LINK, embedded_image, html_page, markdown_to_html, slug
from bodyschema.evaluation.report.pipeline import order_key
from bodyschema.evaluation.report.sections import Section, find_sections, refuse_incomplete
from bodyschema.evaluation.report.trained import trained_sections

NO_RESULTS_HINT = "Run `bodyschema evaluate levels` first."
URL = re.compile(r"[a-zA-Z][\w+.-]*:")


@dataclass(frozen=True)
class ReportConfig:
    """Gather the latest run of every benchmark on each robot under `results` (summary, key figure, plots, tables)
    into one Markdown and one HTML page."""

    results: Path = Path("results")    # the folder benchmarks write into: results/<benchmark>/<run-id>/
    # run folders to report instead of the latest of their benchmark and robot (e.g.
    # results/levels/20261124T201502.123Z-1a2b3c4d); the others: latest
    runs: tuple[Path, ...] = ()
    out: Path | None = None            # the Markdown page, HTML beside it (.html); None: <results>/report.md
    title: str = "bodyschema benchmark report"
    stale_after_s: float = 3600.0      # a plot/CSV this much older than its summary.md is left from an earlier run
    trained: Path | None = Path("runs")  # `bodyschema train`'s --run-root: each model it fitted, a section; None: none

    def __post_init__(self):
        if not self.stale_after_s >= 0:
            raise ValueError(must_be("stale_after_s", "a number of seconds ≥ 0", self.stale_after_s))
        for run in self.runs:
            refuse_incomplete(Path(run))
            if not (Path(run).is_dir() and (Path(run) / "summary.md").is_file()):
                raise ValueError(must_be("runs", "run folders holding a summary.md", str(run),
                                         "Name a folder such as results/levels/<run-id>."))


# ---- the Markdown page ------------------------------------------------------------------------------------
def render_markdown(sections: list[Section], skipped: list[tuple[Path, str]], page_dir: Path, title: str,
                    results: Path) -> str:
    """The report page; links are relative to `page_dir`, where the page is written. Its summary is its contents:
    one linked line per section with the key figure."""
    heads = [s.name.replace("/", " / ") for s in sections]
    n_plots = sum(len(s.plots) for s in sections)
    lines = [f"# {escape_markdown(title)}", "", f"_Generated {_when(time.time())} from "
             f"{escape_markdown(results.as_posix())}/: {len(sections)} sections, {n_plots} plots._", "",
             "## Summary", ""]
    lines += [f"- [{escape_markdown(h)}](#{slug(h)}): {headline(s)}" for h, s in zip(heads, sections)]
    lines += [f"- [Skipped files](#{slug('Skipped files')}): {len(skipped)}"] if skipped else []
    lines += [""]
    for head, section in zip(heads, sections):
        lines += [f"## {escape_markdown(head)}", ""] + _section_body(section, page_dir) + [""]
    if skipped:
        lines += ["## Skipped files", ""]
        lines += [f"- {escape_markdown(_rel(p, page_dir))}: {reason}" for p, reason in skipped] + [""]
    return readable_tables("\n".join(lines))


def _section_body(section: Section, page_dir: Path) -> list[str]:
    files = [section.summary_path, *section.plots, *section.tables]
    newest = max(p.stat().st_mtime for p in files)
    summary, linked = _relink(_demote_headings(section.summary, 2), section.folder, page_dir)
    summary_time = _when(section.summary_path.stat().st_mtime)
    lines = [f"_Folder {escape_markdown(_rel(section.folder, page_dir))}/ · last modified {_when(newest)} "
             f"(summary.md {summary_time})._", "", summary.strip(), ""]
    lines += _models(section.folder / MODELS_CSV, section.folder)
    plots = [p for p in section.plots if p.resolve() not in linked]
    if plots:
        lines += ["**Plots**", ""]
        for p in plots:
            lines += [f"![{escape_markdown(p.stem)}]({_link(p, page_dir)})", "",
                      f"{escape_markdown(p.relative_to(section.folder).as_posix())} · {_when(p.stat().st_mtime)}", ""]
    if section.tables:
        lines += ["**Tables**", ""]
        lines += [f"- [{escape_markdown(p.relative_to(section.folder).as_posix())}]({_link(p, page_dir)}) · "
                  f"{_when(p.stat().st_mtime)}" for p in section.tables]
    return lines


def _models(path: Path, folder: Path) -> list[str]:
    """The run's models (models.csv) as a Markdown table: which weights produced the numbers above."""
    if not (path.is_file() and is_inside(path, folder)):
        return []
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    keys = reader.fieldnames or []
    if not rows or not keys:
        return []
    cells = [{keys[0]: "–"} | {k: v for k, v in r.items() if k in keys and v} for r in rows]   # empty: "–"
    return ["**Models**", "", markdown_table(cells, keys[1:], keys[0])]


def _demote_headings(text: str, by: int) -> str:
    """Headings of a summary.md sit below the section heading: `#` → `###` (at most `######`); code untouched."""
    out, fenced = [], False
    for line in text.splitlines():
        fenced ^= line.lstrip().startswith("```")
        m = None if fenced else re.match(r"(#{1,6})(\s.*)", line)
        out.append("#" * min(6, len(m[1]) + by) + m[2] if m else line)
    return "\n".join(out)


def _relink(text: str, folder: Path, page_dir: Path) -> tuple[str, set[Path]]:
    """Links and images of a summary.md, relative to its folder, rewritten relative to the page; the images found.
    An image outside the folder (absolute, `../`, a symlink elsewhere, a URL) becomes a note: never read."""
    images = set()

    def fix(m: re.Match) -> str:
        target = m[3]
        path = folder / unquote(target)
        if m[1] and (URL.match(target) or not is_inside(path, folder)):     # never read, never fetched
            return f"_(image {escape_markdown(target)} not shown: only files of its run folder are)_"
        if URL.match(target) or target.startswith(("#", "/")):          # a link to a URL, anchor or absolute path
            return m[0]
        if m[1]:
            images.add(resolved(path))
        return f"{m[1]}[{m[2]}]({_link(path, page_dir)})"
    return LINK.sub(fix, text), images


def _rel(path: Path, page_dir: Path) -> str:
    return Path(os.path.relpath(path, page_dir)).as_posix()


def _link(path: Path, page_dir: Path) -> str:
    return quote(_rel(path, page_dir))


def _when(timestamp: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(timestamp))


# ---- writing ----------------------------------------------------------------------------------------------
def write_report(config: ReportConfig = ReportConfig()) -> dict[str, Path]:
    """Write the Markdown and HTML report pages; returns {"markdown": path, "html": path}."""
    results = Path(config.results)
    if not results.is_dir():
        raise ValueError(must_be("results", "a folder holding benchmark outputs", str(results), NO_RESULTS_HINT))
    sections, skipped = find_sections(results, config.stale_after_s, config.runs)
    sections = sorted(sections + trained_sections(config.trained),
                      key=lambda s: order_key(s.benchmark, s.folder_name, s.robot))
    if not sections:
        raise ValueError(must_be("results", "a folder with at least one <benchmark>/summary.md", str(results),
                                 NO_RESULTS_HINT))
    md_path = Path(config.out) if config.out is not None else results / "report.md"
    md_path = md_path.with_suffix(".md")
    md_path.parent.mkdir(parents=True, exist_ok=True)
    page_dir = md_path.parent
    text = render_markdown(sections, skipped, page_dir, config.title, results)
    page = html_page(markdown_to_html(text, embedded_image(page_dir, _embeddable(sections))), config.title)
    paths = {"markdown": md_path, "html": md_path.with_suffix(".html")}
    write_atomically({paths["markdown"]: text, paths["html"]: page})
    return paths


def _embeddable(sections: list[Section]) -> set[Path]:
    """The only files the HTML page reads as images: each run's plots and the images its summary.md shows."""
    plots = {resolved(p) for s in sections for p in s.plots}
    return plots | {p for s in sections for p in _relink(s.summary, s.folder, s.folder)[1]}


def write_atomically(texts: dict[Path, str]) -> None:
    """Write every file to a hidden temporary beside it, then rename them all: a failure leaves no partial file."""
    temps = {}
    try:
        for path, text in texts.items():
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            temps[path] = Path(tmp)
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, 0o644)                                    # mkstemp makes 0600; a report is for reading
        for path, tmp in temps.items():
            os.replace(tmp, path)
    finally:
        for tmp in temps.values():
            tmp.unlink(missing_ok=True)
