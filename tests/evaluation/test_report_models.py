"""Issue 35 item 7: the models table stays inside the page's column (every table in a scrolling box, long digests
and specs wrap), a later run with other models hides no run of the same benchmark and robot (the latest per robot
*and* models), and `success` / `converged` read with their unit."""

import csv
import re
import time
from dataclasses import dataclass
from html.parser import HTMLParser
from pathlib import Path

from bodyschema.evaluation.core.runs import mark_latest, new_run
from bodyschema.evaluation.report import ReportConfig, write_report
from bodyschema.evaluation.report.headers import readable

GPR = "models:/bodyschema-nao_arm-ee_xyz-gpr@champion"
PIXEL = "models:/bodyschema-nao_arm-image-pixel@champion"


@dataclass(frozen=True)
class LevelsLike:
    """A benchmark config that names its robot and models, as levels' run.json does."""

    out: Path
    robot: str
    models: tuple[str, ...]
    seed: int = 0


def levels_run(out: Path, spec: str, err: float, seed: int) -> Path:
    """A finished run with one model: summary.md (a table with success and converged), models.csv, latest moved."""
    time.sleep(0.002)        # run ids order by their millisecond: two runs in one millisecond have no "later" one
    folder = new_run(LevelsLike(out, "nao_arm", (spec,), seed))
    (folder / "summary.md").write_text(f"Levels with {spec}.\n\n| level | mean_err_deg | success | converged |\n"
                                       f"|---|---|---|---|\n| 1 | {err} | 0.9 | 1.0 |\n")
    name = spec.removeprefix("models:/").split("@")[0]
    with open(folder / "models.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, ["spec", "name", "version", "run_id", "sha256", "modality"])
        writer.writeheader()
        writer.writerow({"spec": spec, "name": name, "version": seed + 1, "run_id": "d62ac147f14041749c7365f52ac0a1ba",
                         "sha256": "bbd976992da9529dd912b208923ac77e8cdfa9e609d3919c6585bef2a86cf0d5",
                         "modality": name.split("-")[2]})
    mark_latest(folder)
    return folder


class Tables(HTMLParser):
    """Each <table>'s enclosing element (tag, class) and its header cells."""

    def __init__(self):
        super().__init__()
        self.open, self.tables, self.cell = [], [], None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append({"parent": self.open[-1] if self.open else None, "headers": []})
        if tag == "th":
            self.cell = ""
        self.open.append((tag, dict(attrs).get("class")))

    def handle_endtag(self, tag):
        while self.open and self.open.pop()[0] != tag:
            pass
        if tag == "th":
            self.tables[-1]["headers"].append(self.cell.strip())
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data


def css(page: str) -> dict[str, dict[str, str]]:
    style = re.search(r"<style>(.*?)</style>", page, flags=re.S)[1]
    return {sel.strip(): dict(d.split(":", 1) for d in body.split(";") if d)
            for sel, body in re.findall(r"([^{}]+)\{([^}]*)\}", style)}


def test_the_latest_run_of_each_model_is_reported_and_every_table_fits_the_page(tmp_path):
    results = tmp_path / "results"
    old_gpr = levels_run(results / "levels", GPR, 9.0, seed=0)
    gpr = levels_run(results / "levels", GPR, 1.5, seed=1)
    pixel = levels_run(results / "levels", PIXEL, 3.25, seed=2)               # the robot's latest: hides no GPR run
    paths = write_report(ReportConfig(results=results))
    text = paths["markdown"].read_text()
    heads = [h for h in re.findall(r"^## (.+)$", text, flags=re.M) if h not in ("Summary", "Skipped files")]
    assert sorted(heads) == ["levels · nao_arm · bodyschema-nao_arm-ee_xyz-gpr",
                             "levels · nao_arm · bodyschema-nao_arm-image-pixel"], heads
    assert gpr.name in text and pixel.name in text and old_gpr.name not in text, "the latest run of each model"

    page = paths["html"].read_text()
    parser = Tables()
    parser.feed(page)
    rules = css(page)
    models = [t for t in parser.tables if "weights SHA-256" in t["headers"]]
    assert len(models) == 2 and all("modality" in t["headers"] for t in models), [t["headers"] for t in models]
    for table in parser.tables:
        tag, cls = table["parent"]
        assert tag == "div" and rules[f".{cls}"]["overflow-x"] == "auto" and rules[f".{cls}"]["max-width"] == "100%", \
            f"a table wider than the page's column scrolls inside its box: {table}"
    assert rules["td.long"]["overflow-wrap"] == "anywhere", "a 64-hex digest or a models:/ spec wraps in its cell"
    assert rules["th,td"]["overflow-wrap"] == "break-word", "a short word is never split to narrow its column"
    digests = re.findall(r'<td class="([^"]*)">[0-9a-f]{64}</td>', page)
    assert digests and set(digests) == {"long"}, "the weights' sha256 cells may break anywhere"
    assert rules["td.number"]["white-space"] == "nowrap", "a number never breaks"
    level_headers = next(t["headers"] for t in parser.tables if "level" in t["headers"])
    assert {"success (fraction)", "converged (fraction)"} <= set(level_headers), level_headers


def test_success_and_converged_have_a_unit():
    assert readable("success") == "success (fraction)" and readable("converged") == "converged (fraction)"
    assert readable("goal_success") == "goal success (fraction)"
