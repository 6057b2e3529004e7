"""`--config FILE` (issue 35 item 6): a command's fields from TOML, YAML, JSON or a benchmark's run.json, flags on top;
a run repeated from its run.json writes the same tables; `--version`; shell completion as the README says."""

from __future__ import annotations

import csv
import importlib.metadata
import json
import re
from pathlib import Path

import pytest

from bodyschema.cli import main, parse_command

README = Path(__file__).resolve().parents[1] / "README.md"


def test_file_values_are_used_and_a_flag_overrides_them(tmp_path):
    file = tmp_path / "levels.toml"
    file.write_text('trials = 7\nlevels = [1, 2]\nmultistart = 0\nmodels = ["analytic:planar2:ee_xyz"]\n'
                    "[perception]\nmax_steps = 11\ndt = 0.05\n")               # dt: flat, as --perception.dt is
    config = parse_command(["evaluate", "levels", "--config", str(file), "--trials", "9"])
    assert (config.trials, config.levels, config.multistart, config.models) == (9, (1, 2), 0,
                                                                                 ("analytic:planar2:ee_xyz",))
    assert (config.perception.max_steps, config.perception.flow.dt) == (11, 0.05)
    flags_only = parse_command(["evaluate", "levels", "--trials", "9", "--levels", "1", "2", "--multistart", "0",
                                "--model", "analytic:planar2:ee_xyz", "--perception.max-steps", "11",
                                "--perception.dt", "0.05"])
    assert config == flags_only                                    # the file is what its flags would have said


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_train_reads_yaml_and_json_with_flat_hyper_parameters(tmp_path, suffix):
    values = {"data": "d.zarr", "noise-floor": 1e-5, "seed": 3}
    file = tmp_path / f"train{suffix}"
    file.write_text(json.dumps(values) if suffix == ".json" else "data: d.zarr\nnoise-floor: 1.0e-5\nseed: 3\n")
    config = parse_command(["train", "gpr", "--config", str(file), "--seed", "4"])
    assert (config.data, config.model.noise_floor, config.seed) == (Path("d.zarr"), 1e-5, 4)
    assert config.model.lbfgs_steps == parse_command(["train", "gpr", "--data", "d.zarr"]).model.lbfgs_steps


def test_a_bad_file_is_the_house_error(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("trails = 3\n")
    assert main(["evaluate", "levels", "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "key 'trails'" in err and "must be a field of LevelsConfig" in err and "trials" in err
    assert main(["evaluate", "levels", "--config", str(tmp_path / "none.toml")]) == 2
    assert main(["evaluate", "--config", str(bad)]) == 2
    assert "after a whole command" in capsys.readouterr().err


def _tables(folder: Path) -> dict[str, list[dict]]:
    """Every CSV of a run folder, without what differs between two runs of one config: times."""
    timing = re.compile(r"(^|_)(wall|seconds|time|s)$|wall_s|_ms$")
    return {p.name: [{k: v for k, v in row.items() if not timing.search(k)} for row in csv.DictReader(p.open())]
            for p in sorted(folder.glob("*.csv"))}


def test_a_run_repeated_from_its_run_json_writes_the_same_tables(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    first = ["--quiet", "evaluate", "levels", "--trials", "4", "--runs", "1", "--levels", "1", "2", "--multistart",
             "0", "--no-plots", "--no-mlflow", "--seed", "5", "--out", "results/levels"]
    assert main(first) == 0
    runs = sorted(p for p in (tmp_path / "results" / "levels").iterdir() if not p.is_symlink())
    assert main(["--quiet", "evaluate", "levels", "--config", str(runs[0] / "run.json")]) == 0
    again = sorted(p for p in (tmp_path / "results" / "levels").iterdir() if not p.is_symlink())
    assert len(again) == 2
    record = [json.loads((p / "run.json").read_text()) for p in again]
    assert record[0]["fields"] == record[1]["fields"] and record[0]["fields"]["seed"] == 5
    tables = [_tables(p) for p in again]
    assert set(tables[0]) >= {"runs.csv", "summary.csv", "models.csv"}
    assert tables[0] == tables[1]
    assert again[0].name.split("-")[1] == again[1].name.split("-")[1]       # same config hash, another start time


def test_a_run_json_of_another_benchmark_is_refused(tmp_path, capsys):
    record = tmp_path / "run.json"
    record.write_text(json.dumps({"config": "ReachingConfig", "fields": {"trials": 2}}))
    assert main(["evaluate", "levels", "--config", str(record)]) == 2
    assert "a run of `bodyschema evaluate levels` (LevelsConfig)" in capsys.readouterr().err


def test_version_prints_the_package_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"bodyschema {importlib.metadata.version('bodyschema')}"


def test_the_readme_documents_config_version_and_completion():
    text = README.read_text()
    assert "--config" in text and "bodyschema --version" in text and "--tyro-write-completion" in text


def _leaves(node, words=()):
    from bodyschema import config_file
    members = config_file._members(node)
    if not members:
        yield words
    for member in members:
        yield from _leaves(config_file._inner(member), (*words, config_file._name(member)))


def test_every_command_takes_a_config_file(tmp_path, capsys):
    from bodyschema.commands import tyro_type
    empty = tmp_path / "empty.json"
    empty.write_text("{}")
    leaves = list(_leaves(tyro_type(None)))
    assert ("evaluate", "adaptation", "jupiter") in leaves and ("registry", "promote") in leaves and len(leaves) > 20
    for words in leaves:
        with pytest.raises(SystemExit) as done:
            parse_command([*words, "--config", str(empty), "--help"])
        assert done.value.code == 0, words
    capsys.readouterr()


def test_required_fields_may_come_from_flags(tmp_path):
    empty = tmp_path / "empty.json"
    empty.write_text("{}")
    assert parse_command(["train", "gpr", "--config", str(empty), "--data", "q.zarr"]).data == Path("q.zarr")
    promote = parse_command(["registry", "promote", "--config", str(empty), "NAME", "3"])
    assert (promote.name, promote.version) == ("NAME", 3)
    with pytest.raises(SystemExit):
        parse_command(["train", "gpr", "--config", str(empty)])             # tyro: --data is required
