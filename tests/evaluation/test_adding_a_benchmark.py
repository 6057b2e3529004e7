"""The README's recipe "Adding a benchmark", followed literally: one new file (a module under evaluation/) and one
registry line make `bodyschema evaluate <name>` run it, write a run folder and mark it latest."""

from pathlib import Path

import bodyschema.evaluation
from bodyschema.cli import main
from bodyschema.evaluation import registry
from bodyschema.evaluation.core.runs import latest_run

TOY = '''
from dataclasses import dataclass
from pathlib import Path

from bodyschema.evaluation.core.config import TrialsConfig
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.tables import write_csv


@dataclass(frozen=True)
class CoinConfig(TrialsConfig):
    out: Path = Path("results/coin")


def run_coin(config, models=None):
    flips = eval_rng(config.seed, 0, "targets").integers(0, 2, config.trials)
    folder = new_run(config)
    paths = {"flips": write_csv([{"trial": i, "heads": int(f)} for i, f in enumerate(flips)], folder / "flips.csv")}
    publish(config, folder, "coin", {"heads": float(flips.mean())}, paths)
    return paths
'''


def test_one_file_and_one_registry_line_make_a_benchmark(tmp_path, monkeypatch):
    package = tmp_path / "package"
    package.mkdir()
    (package / "coin_toy.py").write_text(TOY)                                    # the one new file
    monkeypatch.setattr(bodyschema.evaluation, "__path__", [*bodyschema.evaluation.__path__, str(package)])
    line = registry.Benchmark(("coin",), "coin_toy", ("CoinConfig", "run_coin"), "Flip coins.",
                              lambda out: dict(trials=5, out=out, mlflow=False, progress=False))
    monkeypatch.setattr(registry, "BENCHMARKS", (*registry.BENCHMARKS, line))    # the one registry line
    monkeypatch.chdir(tmp_path)
    assert main(["evaluate", "coin", "--trials", "7", "--out", "runs", "--no-mlflow"]) == 0
    run = latest_run(Path("runs"))
    rows = (run / "flips.csv").read_text().splitlines()
    assert rows[0] == "trial,heads" and len(rows) == 8
