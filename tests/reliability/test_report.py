"""`bodyschema report` reads only what belongs to each run and shows user strings as text (issue 25).

- An image link in a summary.md (absolute, `../..`, through a symlink, a URL) or a plot that is a symlink elsewhere
  is dropped with a visible note and never opened; only files inside the run's own folder are embedded.
- Names taken from the file system or a models.csv (a model folder named `[click](http://evil)`, a benchmark
  folder holding `<b>`) are escaped by the one table writer's `escape_markdown`: no live link, no raw HTML.
- `--runs` naming a folder the report would not show is the house error naming both paths.
"""

from __future__ import annotations

import base64
import builtins
import io
import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import pytest

from bodyschema.evaluation.core.specs import provenance_rows, resolve_model
from bodyschema.evaluation.core.tables import markdown_table, write_csv
from bodyschema.evaluation.report import ReportConfig, write_report
from bodyschema.evaluation.report.markdown_html import markdown_to_html
from bodyschema.models.analytic import AnalyticModel
from tests.evaluation.test_report import write_png
from tests.test_cli_fuzz import run_and_check, run_in_process

RUN = "20260101T000000.000Z-0123abcd"
OTHER_RUN = "20260102T000000.000Z-0123abcd"
NASTY = ["[click](http://evil)", "![x](/etc/passwd)", "a|b", "`code` and ``two``", "<b>bold</b>",
         "<img src=x onerror=alert(1)>", "&lt;entity&gt;", "back\\slash \\[", "<http://auto.link>"]


def make_run(results: Path, benchmark: str, run: str = RUN, summary: str = "# Result\n\nAll fine.\n") -> Path:
    folder = results / benchmark / run
    folder.mkdir(parents=True)
    (folder / "summary.md").write_text(summary)
    (results / benchmark / "latest").unlink(missing_ok=True)
    (results / benchmark / "latest").symlink_to(run)
    return folder


def record_opens(monkeypatch) -> list[Path]:
    """From now on, every path opened (builtins.open and pathlib's io.open), resolved."""
    seen, real = [], builtins.open

    def spy(file, *args, **kwargs):
        if isinstance(file, (str, Path)):
            seen.append(Path(file).resolve())
        return real(file, *args, **kwargs)
    monkeypatch.setattr(builtins, "open", spy)
    monkeypatch.setattr(io, "open", spy)
    return seen


def test_images_outside_the_run_folder_are_dropped_with_a_note_and_never_opened(tmp_path, monkeypatch):
    results = tmp_path / "results"
    secret = write_png(tmp_path / "elsewhere" / "secret.png", 99)         # a valid PNG: it would embed if read
    folder = make_run(results, "levels", summary="# Result\n\n" + "\n\n".join([
        f"![absolute]({secret})", "![up](../../../elsewhere/secret.png)", "![linked](linked.png)",
        "![remote](https://example.com/x.png)", "![own](own.png)"]) + "\n")
    write_png(folder / "own.png", 1)
    (folder / "linked.png").symlink_to(secret)                             # inside by name, elsewhere in fact
    (folder / "plot_link.png").symlink_to(secret)                          # would be listed as a plot
    opened = record_opens(monkeypatch)
    paths = write_report(ReportConfig(results=results))
    text, page = paths["markdown"].read_text(), paths["html"].read_text()

    assert secret.resolve() not in opened, "a file outside every run folder was opened"
    assert base64.b64encode(secret.read_bytes()).decode() not in page
    assert base64.b64encode((folder / "own.png").read_bytes()).decode() in page, "the run's own image is embedded"
    for target in (str(secret), "../../../elsewhere/secret.png", "linked.png", "https://example.com/x.png"):
        assert f"image {target} not shown" in text, f"no visible note for {target}"
    skipped = text.split("## Skipped files")[1]
    assert "plot_link.png: outside its run folder" in skipped
    assert page.count("<img ") == 1 and not re.search(r'(src|href)="https?:', page), "no network reference"


def test_any_image_syntax_reaches_only_files_of_the_runs(tmp_path, monkeypatch):
    """Forms the link rewriting does not parse (a title, angle brackets, a reference) still cannot read a file."""
    results = tmp_path / "results"
    secret = write_png(tmp_path / "elsewhere" / "secret.png", 42)
    make_run(results, "levels", summary=f'![t]({secret} "title")\n\n![a](<{secret}>)\n\n![r][ref]\n\n'
                                        f"[ref]: {secret}\n")
    opened = record_opens(monkeypatch)
    page = write_report(ReportConfig(results=results))["html"].read_text()
    assert secret.resolve() not in opened
    assert "<img " not in page and page.count("[missing image:") == 3


class Cells(HTMLParser):
    """The text of every table cell and every link target of an HTML fragment."""

    def __init__(self):
        super().__init__()
        self.cells, self.hrefs, self.tags, self._cell = [], [], [], None

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.hrefs += [v for k, v in attrs if k == "href"]
        if tag in ("td", "th"):
            self._cell = ""

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self.cells.append(self._cell)
            self._cell = None


def parse(html: str) -> Cells:
    cells = Cells()
    cells.feed(html)
    return cells


@pytest.mark.parametrize("name", NASTY)
def test_a_table_cell_shows_any_name_as_itself(name):
    html = markdown_to_html(markdown_table([{"model": name, "spec": name}], ("spec",), "model"))
    cells = parse(html)
    assert cells.cells == ["model", "spec", name, name]
    assert cells.tags.count("div") == 1, "one box around the table (it scrolls), none from the name"
    assert set(cells.tags) - {"div"} == {"table", "thead", "tbody", "tr", "th", "td"}, "no markup from the name"


def test_a_newline_in_a_name_does_not_start_a_new_row_or_block():
    html = markdown_to_html(markdown_table([{"model": "a\n\n# heading\n| x | y |"}], (), "model"))
    assert parse(html).cells == ["model", "a # heading | x | y |"] and "<h1" not in html


def test_a_model_folder_named_like_a_link_is_text_in_the_report(tmp_path):
    results = tmp_path / "results"
    model_dir = tmp_path / "models" / "a`[click](http:" / "evil)`<b>x</b>"    # reads as link syntax, out of code
    AnalyticModel("planar2", "ee_xyz").save(model_dir)
    model = resolve_model(f"trusted:{model_dir}")
    bench = tmp_path / "results" / "odd [x](http:" / "evil) <i>"                # a benchmark folder, as odd
    folder = make_run(results, bench.relative_to(results).as_posix())
    write_csv(provenance_rows([model]), folder / "models.csv")
    write_png(folder / "![p](http:x).png", 3)
    paths = write_report(ReportConfig(results=results))
    page = paths["html"].read_text()
    cells = parse(page)
    for href in cells.hrefs:                          # the contents' anchors and the run's own files, nothing else
        assert href.startswith("#") or (paths["html"].parent / unquote(href)).is_file(), f"a live link: {href}"
    assert "<b>" not in page and "<i>" not in page and page.count("<img ") == 1
    assert f"trusted:{model_dir}" in cells.cells and model.provenance["sha256"] in cells.cells


# ---- --runs: CLI cases in the harness of tests/test_cli_fuzz.py --------------------------------------------
CASES = [
    ("report-runs-outside-results", "report --results {W}/results --runs {W}/outside/" + RUN),
    ("report-runs-two-of-one-benchmark", "report --results {W}/results --runs {W}/results/levels/" + RUN
     + " {W}/results/levels/" + OTHER_RUN),
    ("report-runs-too-deep", "report --results {W}/results --runs {W}/results/levels/" + RUN + "/deeper"),
    ("report-runs-missing", "report --results {W}/results --runs {W}/results/levels/nowhere"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> Path:
    return make_world(tmp_path_factory.mktemp("report_fuzz"))


def make_world(w: Path) -> Path:
    """Results with two levels runs, one run outside --results and a summary nested too deep."""
    make_run(w / "results", "levels", OTHER_RUN)
    make_run(w / "results", "levels")
    make_run(w / "outside", "", RUN)
    deeper = w / "results" / "levels" / RUN / "deeper"
    deeper.mkdir()
    (deeper / "summary.md").write_text("# nested\n")
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_runs_are_a_clear_error(case_id, command, in_world, capsys):
    run_and_check(case_id, command, in_world, capsys)


def test_a_run_outside_results_is_named_with_results(in_world, capsys):
    outside, results = in_world / "outside" / RUN, in_world / "results"
    code, err = run_in_process(["report", "--results", str(results), "--runs", str(outside)], capsys)
    assert code == 2 and str(outside) in err and re.search(rf"outside '{re.escape(str(results))}'", err), err
