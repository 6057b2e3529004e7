"""Issue 35 item 7, as a user sees it: the report in headless Chromium (the Debian package) at 1280 px. The page
never scrolls sideways, and a table wider than the column scrolls inside its own box, so the models table's
sha256 and modality stay reachable; a screenshot is written beside the report. Slow (`make test-all`); skipped
where Chromium is not installed (`apt-get install -y chromium`)."""

import html
import json
import re
import shutil
import subprocess

import pytest

from bodyschema.evaluation.report import ReportConfig, write_report
from tests.evaluation.test_report_models import GPR, PIXEL, levels_run

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
WIDTH = 1280
# Measured in the page once it is laid out: how wide the document is, and per table how far its box reaches and
# whether the box scrolls its own overflow (as the page's CSS says it should).
MEASURE = """<script>
const boxes = [...document.querySelectorAll("table")].map(t => {
  const box = t.parentElement, r = box.getBoundingClientRect();
  return {right: r.right, scrolls: getComputedStyle(box).overflowX === "auto",
          wider: t.scrollWidth > box.clientWidth, headers: [...t.querySelectorAll("th")].map(h => h.textContent)};
});
document.body.setAttribute("data-measured", JSON.stringify(
  {page: document.documentElement.scrollWidth, view: window.innerWidth, boxes}));
</script>"""

pytestmark = [pytest.mark.slow, pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")]


def chromium(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--window-size={WIDTH},900",
                           "--virtual-time-budget=3000", *args], capture_output=True, text=True, timeout=120)


def test_the_report_fits_1280_px_and_wide_tables_scroll_in_their_box(tmp_path):
    results = tmp_path / "results"
    for seed, (spec, err) in enumerate(((GPR, 1.5), (PIXEL, 3.25))):
        levels_run(results / "levels", spec, err, seed=seed)
    wide = levels_run(results / "levels", GPR, 0.5, seed=3)          # per-joint columns of a 24-joint arm
    joints = [f"joint_err_deg/{name}_joint" for name in ("shoulder", "elbow", "wrist", "finger") for _ in range(6)]
    (wide / "summary.md").write_text("| level | " + " | ".join(joints) + " |\n|---|" + "---|" * len(joints) + "\n| 1 | "
                                     + " | ".join(f"{0.123456 * i:.6f}" for i in range(len(joints))) + " |\n")
    page = write_report(ReportConfig(results=results))["html"]
    measured_page = page.with_name("measured.html")
    measured_page.write_text(page.read_text().replace("</body>", MEASURE + "</body>"))
    dom = chromium("--dump-dom", measured_page.as_uri()).stdout
    measured = json.loads(html.unescape(re.search(r'data-measured="([^"]*)"', dom)[1]))
    assert measured["view"] == WIDTH and measured["page"] <= WIDTH, f"the page scrolls sideways: {measured['page']} px"
    models = [b for b in measured["boxes"] if "weights SHA-256" in b["headers"]]
    assert len(models) == 2, [b["headers"] for b in measured["boxes"]]
    assert any(b["wider"] for b in measured["boxes"]), "the 24-joint table is wider than the column"
    for box in measured["boxes"]:
        assert box["right"] <= WIDTH, f"a table's box reaches past the window: {box}"
        assert box["scrolls"] or not box["wider"], f"a table wider than its box is cut, not scrolled: {box}"
    shot = page.with_name("report_1280.png")
    chromium(f"--screenshot={shot}", page.as_uri())
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert int.from_bytes(shot.read_bytes()[16:20], "big") == WIDTH          # the PNG's width (IHDR)
