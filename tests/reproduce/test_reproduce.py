"""`bodyschema reproduce`: the recipes match the README they reproduce, a run continues where a kill left it, the cost
probe scales, and bad flags are the house error."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import pytest

from bodyschema.reproduce import execute, probe, readme_tables, run as reproduce_run, state
from bodyschema.reproduce.config import ReproduceConfig
from bodyschema.reproduce.recipes import RECIPES, Recipe, Row, Step, Table, column

README = Path(__file__).resolve().parents[2] / "README.md"

TINY = Recipe(
    name="tiny", about="planar2, analytic-free: a GP on 64 poses, 2 × 4 levels trials",
    steps=(Step("data", "datagen --robot planar2 --n 64 --no-images --workers 1 --seed 0 --out {run}/data/p.zarr"),
           Step("gp", "train gpr --data {data} --modality ee_xyz --run-root {run}/runs --tracking-uri {tracking}"),
           Step("levels", "evaluate levels --model {gp} --levels 1 --runs 2 --trials 4 --multistart 0 --no-plots "
                          "--out {run}/results/levels --tracking-uri {tracking}")),
    table=Table(marker="tiny", step="levels", csv="summary.csv", key="level", rows=(Row("1 (", "1"),),
                columns=(column("mean", "joint_err_deg"), column("evaluations", "evaluations_per_trial")),
                spread="mean"))
TINY_README = """# A project

<!-- reproduce: tiny -->
| level | mean | evaluations |
|---|---|---|
| 1 (one joint off) | **0.50°** ± 0.25 | 12 |
"""


@pytest.fixture
def tiny(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    monkeypatch.setitem(RECIPES, "tiny", TINY)
    readme = tmp_path / "README.md"
    readme.write_text(TINY_README)
    return ReproduceConfig(only=("tiny",), out=tmp_path / "out", readme=readme, estimate=False)


def _readme_as_results(table: Table, folder: Path) -> dict[str, str]:
    """Results CSVs in `folder` holding the README's own figures where the table maps them; step → its folder."""
    header, rows = readme_tables.readme_table(README, table.marker)
    csvs: dict[tuple[str, str, str], dict[str, dict]] = {}
    for row in table.rows:
        cells = readme_tables.readme_row(table, rows, row)
        for col in table.columns:
            for part, (value, _) in zip(col.parts, readme_tables.figures(cells[header.index(col.readme)],
                                                                            len(col.parts))):
                step, name, key, wanted = readme_tables.part_location(table, row, part)
                record = csvs.setdefault((step, name, key), {}).setdefault(wanted, dict(zip(key.split(","),
                                                                                            wanted.split(","))))
                record[part.result] = "" if value is None else value / part.scale
    for (step, name, _), records in csvs.items():
        (folder / step).mkdir(parents=True, exist_ok=True)
        fields = list(dict.fromkeys(f for r in records.values() for f in r))
        with open(folder / step / name, "w", newline="") as f:
            writer = csv.DictWriter(f, fields)
            writer.writeheader()
            writer.writerows(records.values())
    return {step: str(folder / step) for step, _, _ in csvs}


@pytest.mark.parametrize("name", sorted(RECIPES))
def test_every_recipe_matches_the_readme_it_reproduces(name, tmp_path):
    """Each recipe's marker, rows and columns are in the README, its rows distinct, and results CSVs holding the
    README's own figures compare as zero difference, within its ±."""
    table = RECIPES[name].table
    header, rows = readme_tables.readme_table(README, table.marker)
    found = [readme_tables.readme_row(table, rows, row)[0] for row in table.rows]
    assert len(set(found)) == len(found)
    compared = readme_tables.compare(table, README, _readme_as_results(table, tmp_path))
    assert list(compared) == found
    figures = [cell for cells in compared.values() for cell in cells.values() if cell.readme is not None]
    assert figures and all(cell.difference == pytest.approx(0.0, abs=1e-9) for cell in figures)
    assert all(cell.within is not False for cell in figures)
    if table.spread:
        assert all(cells[table.spread].within for cells in compared.values())


def test_a_cell_of_several_figures_maps_each_to_its_part():
    assert readme_tables.figures("0.003 / 9.8 mm", 2) == [(0.003, None), (9.8, None)]
    assert readme_tables.figures("**72 %** (91 % within 1 px)", 2) == [(72.0, None), (91.0, None)]
    assert readme_tables.figures("92 mm", 2) == [(92.0, None), (None, None)]
    assert readme_tables.figures("2.8 ± 1.1 cm", 1) == [(2.8, 1.1)]


def test_every_recipe_step_has_one_command_and_every_table_step_is_made_by_its_recipe():
    """A shared step (the decoder) is the same command in every recipe that names it."""
    commands = {}
    for recipe in RECIPES.values():
        for step in recipe.steps:
            assert commands.setdefault(step.name, step.command) == step.command
        made = {step.name for step in recipe.steps}
        assert {row.step or recipe.table.step for row in recipe.table.rows} <= made


def test_every_recipe_command_parses_with_the_cli(tmp_path):
    values = {"run": str(tmp_path), "workers": "2", "device": "cpu", "tracking": f"sqlite:///{tmp_path}/m.db"}
    steps = reproduce_run._steps(list(RECIPES.values()))
    configs = reproduce_run._full_configs(steps, values, {})
    assert set(configs) == {s.name for s in steps}


def test_a_readme_figure_is_its_first_number_and_its_spread():
    assert readme_tables.figure("**0.59°** ± 0.01") == (0.59, 0.01)
    assert readme_tables.figure("82.7 %") == (82.7, None)
    assert readme_tables.figure("−1.5e-3 mm") == (-1.5e-3, None)
    assert readme_tables.figure("") == (None, None)


def _fake_steps(ran: list[str], kill_at: str | None):
    """execute.run standing in for the real steps (they have their own tests): it records each config's class,
    raises KeyboardInterrupt at the first `kill_at`, and the levels step writes a summary.csv."""
    def run(config, progress):
        name = type(config).__name__
        ran.append(name)
        if name == kill_at and ran.count(name) == 1:
            raise KeyboardInterrupt
        if name == "LevelsConfig":
            folder = Path(config.out) / "run-1"
            folder.mkdir(parents=True)
            (folder / "summary.csv").write_text("level,joint_err_deg,evaluations_per_trial\n1,0.6,14\n")
            return execute.Done(str(folder))
        return execute.Done(str(getattr(config, "out", None) or "models:/m/1"))
    return run


def test_a_killed_run_continues_at_its_first_unfinished_step(tiny, monkeypatch):
    ran = []
    monkeypatch.setattr(execute, "run", _fake_steps(ran, kill_at="LevelsConfig"))
    with pytest.raises(KeyboardInterrupt):
        reproduce_run.reproduce(tiny)
    folder = state.unfinished(tiny.out, ["tiny"])
    assert set(state.load(folder)["steps"]) == {"data", "gp"}

    tables = reproduce_run.reproduce(tiny)                       # the same command again
    assert ran == ["DatagenConfig", "TrainConfig", "LevelsConfig", "LevelsConfig"]
    assert tables.parent == folder and state.load(folder)["finished"]
    text = tables.read_text()
    assert "| 1 (one joint off) | 0.5 → 0.6 (+0.1) ✓ within ± | 12 → 14 (+2) |" in text
    assert "`bodyschema datagen --robot planar2" in text
    assert state.unfinished(tiny.out, ["tiny"]) is None          # a finished run is not continued: a new one starts


@pytest.mark.slow
def test_a_tiny_recipe_runs_end_to_end(tiny):
    """The real steps: a planar2 store, a GP registered in the run's own MLflow store, levels on it by its URI."""
    tables = reproduce_run.reproduce(tiny)
    assert "| 1 (one joint off) | 0.5 → " in tables.read_text()
    steps = state.load(tables.parent)["steps"]
    assert steps["gp"]["product"].startswith("models:/bodyschema-planar2-ee_xyz-gpr/")


def test_the_cost_probe_scales_a_step_to_its_full_size(tmp_path):
    """The datagen step probed at PROBE_SAMPLES samples: its estimate is the probe's time × n / PROBE_SAMPLES, and
    the probe leaves nothing behind in the run folder."""
    data = TINY.steps[0]
    values = {"run": str(tmp_path / "run"), "workers": "1", "device": "cpu", "tracking": "unused"}
    full = reproduce_run._full_configs([data], values, {})
    big = dataclasses.replace(full["data"], n=probe.PROBE_SAMPLES * 50)
    (cost,) = probe.estimate([data], {}, values, {"data": big})
    assert cost.wall_seconds == pytest.approx(cost.probe_seconds * 50)
    assert 0 < cost.cpu_seconds
    assert not (tmp_path / "run").exists()


def test_an_exact_gp_is_scaled_by_the_samples_of_its_likelihood_not_the_store(tmp_path):
    """A GP on 18 000 poses fits its hyper-parameters on `hyper_points` of them and solves once on at most
    `max_points`: its estimate is the cube of hyper_points / PROBE_ROWS, not of the store's size (which printed 96 h
    for a 20-second fit)."""
    data, gp = TINY.steps[:2]
    values = {"run": str(tmp_path / "run"), "workers": "1", "device": "cpu", "tracking": "unused"}
    full = reproduce_run._full_configs([data, gp], values, {})
    full["data"] = dataclasses.replace(full["data"], n=18000)
    small, scale = probe._shrunk(full["gp"], full["gp"], full)
    assert small.max_train == probe.PROBE_ROWS
    assert scale == pytest.approx((full["gp"].model.hyper_points / probe.PROBE_ROWS) ** 3)


def test_a_dry_run_runs_nothing(tiny, capsys):
    folder = reproduce_run.reproduce(dataclasses.replace(tiny, dry_run=True))
    assert "to do  levels     bodyschema evaluate levels --model <gp>" in capsys.readouterr().out
    assert state.load(folder)["steps"] == {}


@pytest.mark.parametrize("flags, words", [
    (dict(only=("levels", "nope")), "--only must be names among"),
    (dict(device="gpu"), "--device must be cpu, cuda or cuda:N"),
    (dict(workers=0), "--workers must be at least 1"),
    (dict(run_id="x", fresh=True), "one or the other"),
])
def test_bad_flags_are_the_house_error(flags, words):
    with pytest.raises(ValueError, match=words):
        ReproduceConfig(**flags)


def test_a_missing_marker_and_an_unknown_run_are_the_house_error(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("# nothing marked\n")
    with pytest.raises(ValueError, match="must be a table marked <!-- reproduce: levels -->"):
        readme_tables.readme_table(readme, "levels")
    with pytest.raises(FileNotFoundError, match="--run-id must be a reproduce run folder"):
        state.load(tmp_path / "no-such-run")


@pytest.mark.parametrize("change, words", [
    (dict(rows=(Row("9 (", "9"),)), r"must be a row starting '9 \('"),
    (dict(columns=(column("max", "joint_err_deg"),)), r"must be columns \['max'\]"),
])
def test_a_recipe_naming_what_the_readme_lacks_is_the_house_error(tiny, change, words):
    table = dataclasses.replace(TINY.table, **change)
    with pytest.raises(ValueError, match=words):
        readme_tables.compare(table, tiny.readme, {})


def test_only_takes_names_apart_or_comma_separated():
    assert ReproduceConfig(only=("levels,reaching",)).only == ("levels", "reaching")
    assert ReproduceConfig(only=("levels", "reaching")).only == ("levels", "reaching")
