"""`bodyschema report`: sections in the documented order, every plot linked and embedded, Markdown tables become
HTML tables, stale files skipped, the house error on empty results, and no partial file after a failed write."""

import base64
import os
import re
import struct
import zlib
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import pytest
import tyro

from bodyschema.evaluation.report import ReportConfig, page as report, write_report
from bodyschema.evaluation.report.markdown_html import markdown_to_html, slug
from bodyschema.evaluation.report.sections import PNG_SIGNATURE

TABLE = "| level | joint_err_deg |\n|:---|---:|\n| 1 | 0.5 |\n| 3+ms | 2 \\| 3 |\n"


def write_png(path: Path, shade: int) -> Path:
    """A valid 1×1 grey PNG whose bytes differ with `shade`."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(PNG_SIGNATURE + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(bytes([0, shade]))) + chunk(b"IEND", b""))
    return path


def write_benchmark(results: Path, name: str, plots: int = 1) -> list[Path]:
    folder = results / name
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "summary.md").write_text(f"# {name} benchmark\n\nWhat was measured in {name}.\n\n{TABLE}")
    (folder / "episodes.csv").write_text("episode,err\n0,1.0\n")
    return [write_png(folder / f"plot_{k}.png", 10 * k + len(name)) for k in range(plots)]


@pytest.fixture
def results(tmp_path) -> Path:
    results = tmp_path / "results"
    for name in ("zeta", "robustness", "alpha", "self_recognition", "adaptation/marker_shift", "adaptation/jupiter",
                 "reaching", "levels"):
        write_benchmark(results, name)
    write_png(results / "levels" / "extra" / "per_level.png", 200)       # a plot one folder down, no own summary
    return results


def section_names(text: str) -> list[str]:
    return [h for h in re.findall(r"^## (.+)$", text, flags=re.M) if h not in ("Contents", "Skipped files")]


def test_sections_follow_the_documented_order_in_contents_markdown_and_html(results):
    paths = write_report(ReportConfig(results=results))
    text, page = paths["markdown"].read_text(), paths["html"].read_text()
    expected = ["levels", "reaching", "adaptation / jupiter", "adaptation / marker_shift", "self_recognition",
                "robustness", "alpha", "zeta"]
    assert section_names(text) == expected
    contents = text.split("## Contents")[1].split("\n## ")[0]
    assert re.findall(r"^- \[(.+?)\]", contents, flags=re.M) == expected
    anchors = re.findall(r'<a href="#([^"]+)">', page)
    html_heads = re.findall(r'<h2 id="([^"]+)">', page)
    assert anchors == [slug(n) for n in expected]
    assert [h for h in html_heads if h != "contents"] == anchors, "every contents link must reach its heading"


def test_every_plot_is_linked_in_markdown_and_embedded_in_html(results):
    paths = write_report(ReportConfig(results=results))
    text, page = paths["markdown"].read_text(), paths["html"].read_text()
    pngs = sorted(results.rglob("*.png"))
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    linked = {(paths["markdown"].parent / unquote(link)).resolve() for link in links}
    assert len(links) == len(pngs)
    assert linked == {p.resolve() for p in pngs}, "each PNG linked once, by a relative link that resolves"
    for png in pngs:
        assert f"data:image/png;base64,{base64.b64encode(png.read_bytes()).decode()}" in page, png
    assert page.count("data:image/png;base64,") == len(pngs)


def test_the_html_page_is_self_contained(results):
    page = write_report(ReportConfig(results=results))["html"].read_text()
    for ref in re.findall(r'(?:src|href)="([^"]+)"', page):
        assert not re.match(r"(https?:)?//", ref), f"network reference {ref!r} in a self-contained page"
    assert "<link" not in page and "<script" not in page


def test_markdown_and_html_go_where_out_says_with_links_relative_to_the_page(results, tmp_path):
    paths = write_report(ReportConfig(results=results, out=tmp_path / "pages" / "bench.md"))
    assert paths == {"markdown": tmp_path / "pages" / "bench.md", "html": tmp_path / "pages" / "bench.html"}
    for link in re.findall(r"\]\(([^)#]+)\)", paths["markdown"].read_text()):
        assert (paths["markdown"].parent / unquote(link)).is_file(), link


class TableParser(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows, self.tags = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        if tag == "tr":
            self.rows.append([])
        elif tag in ("th", "td"):
            self.rows[-1].append("")

    def handle_data(self, data):
        if self.tags and self.tags[-1] in ("th", "td"):
            self.rows[-1][-1] += data

    def handle_endtag(self, tag):
        self.tags.pop()


def test_a_pipe_table_becomes_an_html_table_with_header_cells_and_alignment():
    html = markdown_to_html("Some text.\n\n" + TABLE + "\n- one\n- two\n")
    parser = TableParser()
    parser.feed(html)
    assert parser.rows == [["level", "joint_err_deg"], ["1", "0.5"], ["3+ms", "2 | 3"]]
    assert len(re.findall(r"<th[ >]", html)) == 2 and len(re.findall(r"<td[ >]", html)) == 4
    assert 'style="text-align:right"' in html and "<p>Some text.</p>" in html
    assert re.search(r"<ul>\s*<li>one</li>\s*<li>two</li>\s*</ul>", html)


def test_headings_code_and_inline_markup_convert_and_escape():
    html = markdown_to_html("## A & B\n\nkeep `x<y` and **bold**, snake_case_name\n\n```python\na < b\n```\n")
    assert '<h2 id="a--b">A &amp; B</h2>' in html
    assert "<code>x&lt;y</code>" in html and "<strong>bold</strong>" in html and "snake_case_name" in html
    assert re.search(r'<pre><code class="language-python">a &lt; b\s*</code></pre>', html)


def test_raw_html_is_shown_as_text_and_a_missing_image_as_its_alt():
    html = markdown_to_html("<script>alert(1)</script>\n\n![the plot](gone.png)\n", lambda src: None)
    assert "<script" not in html and "&lt;script&gt;" in html
    assert "<em>[missing image: the plot]</em>" in html and "<img" not in html


def test_an_image_link_is_unquoted_before_it_is_mapped():
    seen = []
    html = markdown_to_html("![p](runs/a%20b/plot.png)", lambda src: seen.append(src) or "data:image/png;base64,AA")
    assert seen == ["runs/a b/plot.png"] and '<img src="data:image/png;base64,AA" alt="p">' in html


def test_stale_truncated_and_orphan_files_are_skipped_and_listed(results):
    stale = results / "levels" / "plot_0.png"
    old = (results / "levels" / "summary.md").stat().st_mtime - 2 * 3600
    os.utime(stale, (old, old))
    broken = results / "reaching" / "plot_0.png"
    broken.write_bytes(broken.read_bytes()[4:])                           # lost its PNG signature
    write_png(results / "orphan" / "lonely.png", 7)                       # outputs without a summary.md
    paths = write_report(ReportConfig(results=results))
    text, page = paths["markdown"].read_text(), paths["html"].read_text()
    skipped = text.split("## Skipped files")[1]
    assert "levels/plot_0.png" in skipped and "stale" in skipped
    assert "reaching/plot_0.png" in skipped and "not a PNG" in skipped and "orphan" in skipped
    assert "](levels/plot_0.png)" not in text.split("## Skipped files")[0]
    assert base64.b64encode(stale.read_bytes()).decode() not in page


@pytest.mark.parametrize("make", ["missing", "empty", "no_summary"])
def test_no_results_raises_the_house_error_with_a_hint(tmp_path, make):
    results = tmp_path / "results"
    if make != "missing":
        results.mkdir()
    if make == "no_summary":
        write_png(results / "levels" / "plot.png", 1)
    with pytest.raises(ValueError, match=r"results must be .*Run `bodyschema evaluate levels` first\."):
        write_report(ReportConfig(results=results))
    assert not (results / "report.md").exists() and not (results / "report.html").exists()


def test_a_failing_write_leaves_no_partial_file_and_keeps_the_old_report(results, monkeypatch):
    paths = write_report(ReportConfig(results=results))
    before = {p: p.read_bytes() for p in paths.values()}
    write_benchmark(results, "reaching", plots=3)                         # the next report would differ
    calls = []

    def disk_full(fd):
        calls.append(fd)
        if len(calls) == 2:                                               # the Markdown is out, the HTML is not
            raise OSError(28, "No space left on device")
    monkeypatch.setattr(report.os, "fsync", disk_full)
    with pytest.raises(OSError, match="No space"):
        write_report(ReportConfig(results=results))
    assert {p: p.read_bytes() for p in paths.values()} == before, "the previous report must stay whole"
    assert not [p for p in results.iterdir() if p.name.endswith(".tmp")], "no temporary file may be left"


def test_config_is_a_tyro_cli_and_rejects_a_negative_staleness(tmp_path):
    config = tyro.cli(ReportConfig, args=["--results", str(tmp_path), "--title", "Mine"])
    assert config == ReportConfig(results=tmp_path, title="Mine")
    with pytest.raises(ValueError, match="stale_after_s must be"):
        ReportConfig(stale_after_s=-1.0)
