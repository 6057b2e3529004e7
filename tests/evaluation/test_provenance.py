"""What a `--model` spec resolved to is recorded: a registry alias is pinned to one version, and the run's
models.csv, its MLflow tags and the report name that version, its source run and its weights digest."""

from __future__ import annotations

import csv

import mlflow

from bodyschema.evaluation.core.runs import latest_run
from bodyschema.evaluation.core.specs import resolve_model
from bodyschema.evaluation.levels import LevelsConfig, run_levels
from bodyschema.evaluation.report import ReportConfig, write_report
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config


def test_a_registry_alias_is_recorded_as_the_version_run_and_digest_it_resolved_to(workdir, kin_store, tiny_kind):
    result = train(tiny_config(kin_store, epochs=3))
    name, version = result.registered_name, result.model_version
    spec = f"models:/{name}@champion"
    model = resolve_model(spec)
    want = {"spec": spec, "name": name, "version": version, "run_id": result.run_id,
            "sha256": result.registered[0].model_sha256}
    assert model.provenance == want

    summary = run_levels(LevelsConfig(models=(spec,), levels=(1,), trials=3, runs=1, multistart=0, plots=False,
                                      progress=False, out=workdir / "results" / "levels"))
    with open(summary.paths["models_csv"], newline="") as f:
        assert [dict(r) for r in csv.DictReader(f)] == [{**want, "modality": "ee_xyz"}]
    tags = mlflow.get_run(summary.run_id).data.tags
    assert {k: tags[f"bodyschema.model.0.{k}"] for k in want} == want

    page = write_report(ReportConfig(results=workdir / "results"))["markdown"].read_text()
    section = page[page.index("## levels"):]
    assert f"| {version} | {result.run_id} | {want['sha256']} | ee_xyz |" in section     # the Models table row
    assert latest_run(workdir / "results" / "levels").name in section
