"""Run folders are complete only after their last write (issue 32, item 18): `evaluate levels --targets` killed
mid-run leaves a run folder marked incomplete, which `report` skips and names, `--runs` refuses, and the next run of
the benchmark removes (its writer is gone); a run still going, or one from before the marker, is left alone."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bodyschema.evaluation.core.runs import RUN_FILE, is_complete, is_run_folder, latest_run, new_run, remove_abandoned
from bodyschema.evaluation.report import ReportConfig, write_report
from tests.datagen.import_sources import planar2_frames, write_folder
from tests.reliability.test_import import _stores

LEVELS = ["evaluate", "levels", "--model", "analytic:planar2:ee_xyz", "--trials", "2", "--runs", "1", "--no-mlflow"]


@pytest.fixture(scope="module")
def targets(tmp_path_factory) -> Path:
    w = tmp_path_factory.mktemp("run_completion")
    q, images = planar2_frames(6)
    write_folder(w / "rec", q, images)
    _stores(w)
    return w / "fk.zarr"


def _levels(out: Path, targets: Path) -> list[str]:
    return [sys.executable, "-m", "bodyschema.cli", *LEVELS, "--targets", str(targets), "--out", str(out)]


def _kill_when_run_folder_appears(command: list[str], out: Path) -> Path:
    """Start `command`, SIGKILL it as soon as its new run folder under `out` holds run.json; → that folder."""
    before = set(out.iterdir()) if out.is_dir() else set()
    env = {k: v for k, v in os.environ.items() if k not in ("MLFLOW_TRACKING_URI", "BODYSCHEMA_DEBUG")}
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and process.poll() is None:
            runs = [p for p in out.glob("*") if p not in before and is_run_folder(p) and (p / RUN_FILE).is_file()]
            if runs:
                os.kill(process.pid, signal.SIGKILL)
                break
            time.sleep(0.005)
    finally:
        process.kill()
        process.wait()
    (folder,) = [p for p in out.iterdir() if p not in before and is_run_folder(p)]
    return folder


def test_a_killed_levels_run_is_incomplete_skipped_by_report_and_removed_by_the_next_run(tmp_path, targets):
    results = tmp_path / "results"
    out = results / "levels"
    killed = _kill_when_run_folder_appears(_levels(out, targets), out)
    if is_complete(killed):
        pytest.skip("the run finished before it could be killed (a very fast machine)")
    assert not (out / "latest").exists() and latest_run(out) is None, "an incomplete run is never the latest"
    done = subprocess.run(_levels(out, targets), capture_output=True, text=True, timeout=300,
                          env={k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"})
    assert done.returncode == 0, done.stderr
    assert not killed.exists(), "the next run removed the killed one (its writer is gone)"
    finished = latest_run(out)
    assert is_complete(finished) and (finished / "targets.json").is_file()


def test_report_names_an_incomplete_run_and_refuses_it_in_runs(tmp_path, targets, capsys):
    from bodyschema.cli import main

    results = tmp_path / "results"
    out = results / "levels"
    assert main([*LEVELS, "--targets", str(targets), "--out", str(out)]) == 0
    finished = latest_run(out)
    killed = _kill_when_run_folder_appears(_levels(out, targets), out)
    if is_complete(killed):
        pytest.skip("the run finished before it could be killed (a very fast machine)")
    text = write_report(ReportConfig(results=results))["markdown"].read_text()
    assert finished.name in text
    assert f"{killed.name}: an incomplete run (killed, or still running): not reported" in text
    assert main(["report", "--results", str(results), "--runs", str(killed)]) == 2
    assert "runs must be complete runs" in capsys.readouterr().err


def test_a_run_still_going_and_a_run_from_before_the_marker_are_left_alone(tmp_path):
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Config:
        out: Path
        seed: int = 0

    mine = new_run(Config(tmp_path))                                    # this process writes it: still going
    old = tmp_path / "20260101T000000.000Z-00000000"
    old.mkdir()
    record = json.loads((mine / RUN_FILE).read_text())
    (old / RUN_FILE).write_text(json.dumps({k: v for k, v in record.items() if k not in ("complete", "writer")}))
    other_host = tmp_path / "20260101T000000.001Z-00000000"
    other_host.mkdir()
    (other_host / RUN_FILE).write_text(json.dumps({**record, "writer": {**record["writer"], "host": "elsewhere"}}))
    assert remove_abandoned(tmp_path) == []
    assert not is_complete(mine) and is_complete(old) and not is_complete(other_host)
    assert latest_run(tmp_path) == old, "the newest complete run, never an incomplete one"


def test_runs_refuses_a_run_killed_before_its_summary_as_incomplete(tmp_path, capsys):
    """The window the kill test can land in under load: run.json written, summary.md not yet. --runs names it an
    incomplete run, as it does one killed later, not a folder that is no run."""
    from dataclasses import dataclass

    from bodyschema.cli import main

    @dataclass(frozen=True)
    class Config:
        out: Path
        seed: int = 0

    early = new_run(Config(tmp_path / "results" / "levels"))
    assert not (early / "summary.md").exists() and not is_complete(early)
    assert main(["report", "--results", str(tmp_path / "results"), "--runs", str(early)]) == 2
    assert "runs must be complete runs" in capsys.readouterr().err
