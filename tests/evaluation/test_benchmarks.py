"""Every registered benchmark (evaluation/registry.py), checked once here, as the model contract checks every model:
the same seed writes the same CSVs (wall-clock columns aside), a run never overwrites another, `latest` names the
newest run, and the CLI's evaluate group is the registry."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest

from bodyschema.evaluation import registry
from bodyschema.evaluation.core.runs import LATEST, RUN_NAME, config_hash, latest_run, run_id
from bodyschema.evaluation.core.tables import is_wall_column

IDS = [" ".join(b.words) for b in registry.BENCHMARKS]


def read_csvs(folder: Path) -> dict[str, list[dict]]:
    """Every CSV of a run folder, wall-clock columns dropped: name → rows."""
    out = {}
    for path in sorted(folder.rglob("*.csv")):
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        out[path.relative_to(folder).as_posix()] = [{k: v for k, v in r.items() if not is_wall_column(k)}
                                                    for r in rows]
    return out


@pytest.mark.parametrize("bench", registry.BENCHMARKS, ids=IDS)
def test_same_seed_same_csvs(bench, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in ("a", "b"):
        bench.run(bench.tiny(tmp_path / name))
    first, second = latest_run(tmp_path / "a"), latest_run(tmp_path / "b")
    tables, again = read_csvs(first), read_csvs(second)
    assert tables, f"{bench.words}: the run wrote no CSV"
    assert tables.keys() == again.keys()
    for name in tables:
        assert tables[name] == again[name], f"{' '.join(bench.words)}: {name} differs between two runs of one seed"


def test_a_second_run_never_overwrites_the_first_and_latest_follows(tmp_path):
    bench = registry.BENCHMARKS[0]
    config = bench.tiny(tmp_path)
    bench.run(config)
    first = latest_run(tmp_path)
    before = {p.name: p.read_bytes() for p in first.iterdir()}
    bench.run(config)
    second = latest_run(tmp_path)
    assert second != first and second.name > first.name, "run ids sort by time"
    assert {p.name: p.read_bytes() for p in first.iterdir()} == before, "the first run's files are untouched"
    assert os.readlink(tmp_path / LATEST) == second.name, "latest: a relative link to the newest run"
    assert sorted(p.name for p in tmp_path.iterdir() if RUN_NAME.match(p.name)) == [first.name, second.name]


def test_run_id_is_utc_time_and_config_hash():
    bench = registry.BENCHMARKS[0]
    a, b = bench.tiny(Path("x")), bench.tiny(Path("y"))
    assert config_hash(a) != config_hash(b) and config_hash(a) == config_hash(bench.tiny(Path("x")))
    assert run_id(a, now=0.0) == f"19700101T000000.000Z-{config_hash(a)}"
    assert RUN_NAME.match(run_id(a))


def test_the_cli_evaluate_group_is_the_registry(capsys):
    from bodyschema import commands
    from bodyschema.cli import main
    assert all(commands.find(("evaluate", *b.words)).config() is b.config for b in registry.BENCHMARKS)
    for bench in registry.BENCHMARKS:
        with pytest.raises(SystemExit) as exit_:
            main(["evaluate", *bench.words, "--help"])
        assert exit_.value.code == 0
        text = capsys.readouterr().out
        for flag in ("--seed", "--out", "--no-mlflow", "--no-progress", "--trials"):
            assert flag in text, f"evaluate {' '.join(bench.words)} lacks {flag}"
        assert "seeds every random draw" in text and "Vision drives action" not in text, "help of its own field"


def test_report_shows_each_benchmarks_latest_run_or_the_runs_named(tmp_path):
    from bodyschema.evaluation.report import ReportConfig, write_report
    results = tmp_path / "results"
    for bench in registry.BENCHMARKS[:2]:                                   # levels and robustness, twice each
        for _ in range(2):
            bench.run(bench.tiny(results / bench.words[0]))
    levels = sorted(p for p in (results / "levels").iterdir() if RUN_NAME.match(p.name))
    page = write_report(ReportConfig(results=results))["markdown"].read_text()
    assert levels[1].name in page and levels[0].name not in page, "latest only"
    assert page.count("## levels") == 1 and page.count("## robustness") == 1
    page = write_report(ReportConfig(results=results, runs=(levels[0],)))["markdown"].read_text()
    assert levels[0].name in page and levels[1].name not in page, "the run named with --runs"
    with pytest.raises(ValueError, match="runs must be run folders"):
        ReportConfig(results=results, runs=(results / "nowhere",))
