"""`bodyschema report`: sections in pipeline order, one per benchmark and robot (no run hides another), a summary line
per section with its key figure, readable table headers, tables that wrap or scroll inside the page, every plot
linked and embedded, Markdown tables become HTML tables, stale files skipped, the house error on empty results, and no
partial file after a failed write."""

import base64
import json
import os
import re
import struct
import zlib
from dataclasses import dataclass
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import pytest
import tyro

from bodyschema.evaluation.core.runs import LATEST, mark_latest, new_run
from bodyschema.evaluation.report import ReportConfig, page as report, write_report
from bodyschema.evaluation.report.headers import readable
from bodyschema.evaluation.report.markdown_html import STYLE, markdown_to_html, slug
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
    return [h for h in re.findall(r"^## (.+)$", text, flags=re.M) if h not in ("Summary", "Skipped files")]


def summary_lines(text: str) -> dict[str, str]:
    """The page's summary: section name → its key figure."""
    summary = text.split("## Summary")[1].split("\n## ")[0]
    return dict(re.findall(r"^- \[(.+?)\]\(#[^)]*\): (.*)$", summary, flags=re.M))


def test_sections_follow_the_pipeline_order_in_summary_markdown_and_html(results):
    paths = write_report(ReportConfig(results=results))
    text, page = paths["markdown"].read_text(), paths["html"].read_text()
    expected = ["levels", "robustness", "reaching", "adaptation / jupiter", "adaptation / marker_shift",
                "self_recognition", "alpha", "zeta"]                      # the README's pipeline, then others A→Z
    assert section_names(text) == expected
    assert list(summary_lines(text)) == expected
    anchors = re.findall(r'<a href="#([^"]+)">', page)
    html_heads = re.findall(r'<h2 id="([^"]+)">', page)
    assert anchors == [slug(n) for n in expected]
    assert [h for h in html_heads if h != "summary"] == anchors, "every summary link must reach its heading"


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


# ---- one section per benchmark and robot --------------------------------------------------------------------
@dataclass(frozen=True)
class RobotConfig:
    """A benchmark config that names its robot, as reaching's does."""

    out: Path
    robot: str
    seed: int = 0


def reaching_run(out: Path, robot: str, aif: float, pd: float, seed: int = 0) -> Path:
    """A finished run on `robot` as run_reaching leaves it: run.json, summary.md, summary.csv, latest links moved."""
    folder = new_run(RobotConfig(out, robot, seed))
    table = f"| controller | success |\n|---|---|\n| aif | {aif} |\n"
    (folder / "summary.md").write_text(f"Reaching on {robot}.\n\n{table}")
    (folder / "summary.csv").write_text(f"controller,episodes,success\naif,4,{aif}\npd,4,{pd}\n")
    mark_latest(folder)
    return folder


def test_a_run_on_another_robot_hides_no_run(tmp_path):
    results = tmp_path / "results"
    first = reaching_run(results / "reaching", "nao_arm", 0.0, 1.0)
    nao = reaching_run(results / "reaching", "nao_arm", 0.5, 1.0, seed=1)
    panda = reaching_run(results / "reaching", "panda", 0.25, 0.75)
    assert json.loads((panda / "run.json").read_text())["robot"] == "panda"
    assert os.readlink(results / "reaching" / LATEST) == panda.name, "latest: the newest run of any robot"
    assert os.readlink(results / "reaching" / f"{LATEST}-nao_arm") == nao.name, "panda's run moved nao_arm's not"
    text = write_report(ReportConfig(results=results))["markdown"].read_text()
    assert section_names(text) == ["reaching · nao_arm", "reaching · panda"]
    assert nao.name in text and panda.name in text and first.name not in text, "each robot's latest run, only"
    lines = summary_lines(text)
    assert "AIF 50 % vs PD 100 %" in lines["reaching · nao_arm"] and "AIF 25 % vs PD 75 %" in lines["reaching · panda"]


def test_a_run_named_with_runs_replaces_its_own_robots_latest_only(tmp_path):
    results = tmp_path / "results"
    first = reaching_run(results / "reaching", "nao_arm", 0.0, 1.0)
    nao = reaching_run(results / "reaching", "nao_arm", 0.5, 1.0, seed=1)
    panda = reaching_run(results / "reaching", "panda", 0.25, 0.75)
    text = write_report(ReportConfig(results=results, runs=(first,)))["markdown"].read_text()
    assert first.name in text and panda.name in text and nao.name not in text
    with pytest.raises(ValueError, match="runs must be .*one run per benchmark and robot"):
        write_report(ReportConfig(results=results, runs=(first, nao)))


def test_a_results_folder_from_before_run_json_still_reports(tmp_path):
    old = tmp_path / "results" / "reaching"
    runs = [old / f"2026010{k}T000000.000Z-0000000{k}" for k in (1, 2)]
    for run, aif in zip(runs, (0.0, 0.5)):
        run.mkdir(parents=True)
        (run / "summary.md").write_text("| controller | success |\n|---|---|\n| aif | 1 |\n")
        (run / "summary.csv").write_text(f"controller,episodes,success\naif,2,{aif}\npd,2,1.0\n")
    os.symlink(runs[0].name, old / LATEST)                                # written by the old mark_latest
    text = write_report(ReportConfig(results=tmp_path / "results"))["markdown"].read_text()
    assert section_names(text) == ["reaching"] and runs[0].name in text and runs[1].name not in text
    assert "AIF 0 % vs PD 100 %" in summary_lines(text)["reaching"]
    panda = reaching_run(old, "panda", 0.25, 0.75)                        # a new run beside the old ones
    text = write_report(ReportConfig(results=tmp_path / "results"))["markdown"].read_text()
    assert section_names(text) == ["reaching · panda"] and panda.name in text


def test_sections_of_benchmarks_and_robots_follow_the_pipeline(tmp_path):
    results = tmp_path / "results"
    for name in ("agency", "rubber_hand", "self_recognition", "adaptation/jupiter", "loop_robustness",
                 "robustness", "levels_gpr", "levels", "tracking"):
        write_benchmark(results, name)
    reaching_run(results / "reaching", "panda", 0.0, 1.0)
    reaching_run(results / "reaching", "nao_arm", 0.0, 1.0)
    text = write_report(ReportConfig(results=results))["markdown"].read_text()
    assert section_names(text) == ["levels", "levels_gpr", "robustness", "tracking", "reaching · nao_arm",
                                   "reaching · panda", "loop_robustness", "adaptation / jupiter", "self_recognition",
                                   "rubber_hand", "agency"]


# ---- the summary: one line per section with its key figure ------------------------------------------------------
def test_the_summary_has_one_line_per_section_with_its_key_figure(results):
    (results / "levels" / "summary.csv").write_text("level,joint_err_deg\n1,0.5\n2,1.25\n3+ms,20\n")
    (results / "self_recognition" / "summary.csv").write_text("comparison,auc,tpr,fpr\npooled,0.875,0.9,0.1\n")
    (results / "reaching" / "summary.csv").write_text("controller,episodes,joint_err_deg\naif,2,1\npd,2,2\n")
    text = write_report(ReportConfig(results=results))["markdown"].read_text()
    lines = summary_lines(text)
    assert list(lines) == section_names(text), "one line per section, in the sections' order"
    assert lines["levels"] == "mean joint error L1 0.5° · L2 1.25° · L3+ms 20°"
    assert lines["self_recognition"].startswith("AUC own body vs others 0.875 (pooled; TPR 0.9 at FPR 0.1)")
    assert lines["reaching"] == "key figure unavailable (no number in column success)", "an older CSV"
    assert lines["robustness"] == "key figure unavailable (no noise_sweep.csv)"
    assert lines["zeta"] == "no key figure defined for this benchmark: see its section"


def test_the_tracking_line_gives_the_trackers_error_time_and_lost_track_beside_the_other_methods(tmp_path):
    results = tmp_path / "results"
    write_benchmark(results, "tracking")
    header = "rate_hz,condition,method,joint_err_deg,lost_events,wall_s_frame_median\n"
    table = [("30", "image", "encoder", 9.5, 0, 0.001), ("30", "image", "flow", 4.25, 3, 0.004),
             ("30", "image", "tracker", 2.5, 1, 0.0125), ("60", "image", "tracker", 1.75, 0, 0.01)]
    (results / "tracking" / "summary.csv").write_text(header + "".join(",".join(map(str, r)) + "\n" for r in table))
    line = summary_lines(write_report(ReportConfig(results=results))["markdown"].read_text())["tracking"]
    assert line == ("30 Hz, image: tracker 2.5° mean joint error (encoder 9.5°, flow 4.25°), 12.5 ms per frame "
                    "(median), 1 lost-track events · 60 Hz, image: tracker 1.75° mean joint error, 10 ms per frame "
                    "(median), 0 lost-track events")
    cpu = "rate_hz,condition,method,joint_err_deg,lost_events,wall_s_frame_median,wall_s_frame_cpu_median\n"
    (results / "tracking" / "summary.csv").write_text(cpu + "30,image,tracker,2.5,1,0.04,0.0105\n")
    line = summary_lines(write_report(ReportConfig(results=results))["markdown"].read_text())["tracking"]
    assert line == ("30 Hz, image: tracker 2.5° mean joint error, 40 ms per frame (median, 10.5 ms of CPU), "
                    "1 lost-track events")
    (results / "tracking" / "summary.csv").write_text(header + "30,image,flow,4.25,3,0.004\n")
    line = summary_lines(write_report(ReportConfig(results=results))["markdown"].read_text())["tracking"]
    assert line == "key figure unavailable (summary.csv lacks the tracker row at 30 Hz, image)"


def test_a_plain_models_folder_gets_its_models_floor_as_its_line(tmp_path):
    results = tmp_path / "results"
    write_benchmark(results, "models")
    (results / "models" / "models.csv").write_text("model,train_samples,epochs,floor_deg\ngp v1,1500,,\n"
                                                   "dec v2,1638,30,2.5\n")
    line = summary_lines(write_report(ReportConfig(results=results))["markdown"].read_text())["models"]
    assert line == "dec v2 (30 epochs on 1638 samples): floor 2.5° mean joint error, started at the truth"


# ---- readable headers ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("column, header", [
    ("mean_err_deg", "mean error (°)"), ("joint_err_median_deg", "median joint error (°)"),
    ("ee_err_mm", "ee error (mm)"), ("time_to_reach_s", "time to reach (s)"), ("drift_cm_std", "drift std (cm)"),
    ("joint_err_deg/shoulder", "joint error, shoulder (°)"), ("auc", "AUC"), ("sha256", "weights SHA-256"),
    ("level", "level"), ("median ms", "median ms"), ("σ (rad)", "σ (rad)")])
def test_a_snake_case_column_reads_as_words_with_its_unit(column, header):
    assert readable(column) == header


def test_every_table_header_on_the_page_is_mapped_and_code_is_not(tmp_path):
    folder = tmp_path / "results" / "levels"
    folder.mkdir(parents=True)
    (folder / "summary.md").write_text("| level | mean_err_deg | ee_err_mm |\n|:--|--:|--:|\n| 1 | 2.48e-05 | 3 |\n\n"
                                       "```\n| raw_name |\n|---|\n```\n")
    (folder / "models.csv").write_text("spec,name,version,run_id,sha256\nanalytic:nao_arm:ee_xyz,x,,,no weights\n")
    paths = write_report(ReportConfig(results=tmp_path / "results"))
    text, page = paths["markdown"].read_text(), paths["html"].read_text()
    assert "| level | mean error (°) | ee error (mm) |\n|:--|--:|--:|" in text
    assert "| name | version | source run | weights SHA-256 |" in text, "the models table too"
    assert "| raw_name |" in text, "a table inside fenced code is code: left as written"
    parser = TableParser()
    parser.feed(page)
    assert ["level", "mean error (°)", "ee error (mm)"] in parser.rows
    assert not [c for row in parser.rows for c in row if re.fullmatch(r"[a-z]+(_[a-z0-9]+)+", c)], "no snake_case"


# ---- tables that fit ------------------------------------------------------------------------------------------
def css_rules(page: str) -> dict[str, str]:
    style = re.search(r"<style>(.*?)</style>", page, flags=re.S)[1]
    return {selector.strip(): body for selector, body in re.findall(r"([^{}]+)\{([^}]*)\}", style)}


def test_a_wide_table_wraps_or_scrolls_inside_its_section(results):
    page = write_report(ReportConfig(results=results))["html"].read_text()
    rules = css_rules(page)
    assert rules == css_rules(f"<style>{STYLE}</style>")
    box = dict(d.split(":", 1) for d in rules[".table-scroll"].split(";"))
    assert box["max-width"] == "100%" and box["overflow-x"] == "auto", \
        "a table wider than the text scrolls inside its box instead of running past the page's edge"
    assert "nowrap" not in rules["th,td"] + rules.get("th", ""), "header words and text cells may wrap"
    assert "white-space:nowrap" in rules["td.number"], "a number is never broken at its '-'"
    assert '<td class="number">2.201e-05</td>' in markdown_to_html("| a | b |\n|---|---|\n| x y | 2.201e-05 |\n")


def test_a_levels_run_names_its_models_robot_so_another_robots_levels_stay_in_the_report(tmp_path):
    from bodyschema.evaluation.levels import LevelsConfig, run_levels
    results = tmp_path / "results"
    tiny = dict(trials=2, runs=1, multistart=0, plots=False, mlflow=False, progress=False, out=results / "levels")
    nao = run_levels(LevelsConfig(**tiny, models=("analytic:nao_arm:ee_xyz",))).paths["summary_md"].parent
    planar = run_levels(LevelsConfig(**tiny, models=("analytic:planar2:ee_xyz",))).paths["summary_md"].parent
    assert json.loads((planar / "run.json").read_text())["robot"] == "planar2", "the models' body, recorded"
    assert os.readlink(results / "levels" / f"{LATEST}-nao_arm") == nao.name
    text = write_report(ReportConfig(results=results))["markdown"].read_text()
    assert section_names(text) == ["levels · nao_arm", "levels · planar2"]
