"""What MLflow's run page can show (issue 35 item 4), read back with MLflow's own client: an evaluation run has the
store its model was trained on as a dataset input (the store's digest) and the model version it used as logged models
of its own experiment; it starts when the benchmark does and ends when it is logged; experiments carry a description
and the tag that opens the UI in its classic ML mode; a training run holds its model card, dataset summary and loss
curves as artifacts."""

from __future__ import annotations

import shutil
import time

import pytest
from mlflow import MlflowClient

from bodyschema.evaluation import registry
from bodyschema.evaluation.core.mlflow_log import REFERENCE_TAG
from bodyschema.evaluation.levels import LevelsConfig
from bodyschema.training.data import load_dataset
from bodyschema.training.registry import CLASSIC_ML, KIND_TAG
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config

NAME = "bodyschema-planar2-ee_xyz-tiny"
NOTE = "mlflow.note.content"


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory, empty_db, kin_store):
    """One tiny model trained and registered, one levels run of it through the registry's runner (what `bodyschema
    evaluate levels` calls), timed from outside; → (client, version, training run, evaluation run, (t0, t1) s)."""
    from bodyschema.models import kinds
    from tests.training.tiny_model import TINY

    folder = tmp_path_factory.mktemp("run_page")
    shutil.copy(empty_db, folder / "mlflow.db")
    levels = next(b for b in registry.BENCHMARKS if b.words == ("levels",))
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        patch.delenv("MLFLOW_TRACKING_URI", raising=False)
        patch.setitem(kinds.KINDS, "tiny", TINY)
        result = train(tiny_config(kin_store, epochs=3))
        config = LevelsConfig(models=(f"models:/{NAME}@champion",), levels=(1,), trials=3, runs=1, multistart=0,
                              plots=False, progress=False, out=folder / "results" / "levels")
        t0 = time.time()
        summary = levels.run(config)
        t1 = time.time()
        client = MlflowClient()
        yield (client, client.get_model_version(NAME, result.model_version), client.get_run(result.run_id),
               client.get_run(summary.run_id), (t0, t1))


def test_the_evaluation_run_lists_the_store_its_model_was_trained_on(evaluated, kin_store):
    client, version, _, run, _ = evaluated
    digest = load_dataset(kin_store, "ee_xyz").sha256
    assert version.tags["dataset_sha256"] == digest
    inputs = run.inputs.dataset_inputs
    assert [(i.dataset.name, i.dataset.digest) for i in inputs] == [(kin_store.name, digest[:32])]
    tags = {t.key: t.value for t in inputs[0].tags}
    assert tags == {"mlflow.data.context": "training", "model": f"{NAME}-v{version.version}"}


def test_the_evaluation_run_lists_the_version_it_used_in_its_own_experiment(evaluated):
    client, version, _, run, _ = evaluated
    model_id = version.source.removeprefix("models:/")
    ids = {m.model_id for m in run.inputs.model_inputs}
    assert model_id in ids and len(ids) == 2                      # the version's own model and its reference
    reference = client.get_logged_model((ids - {model_id}).pop())
    # MLflow's run page searches the run's experiment for the logged models among its inputs: the reference is there
    assert reference.experiment_id == run.info.experiment_id != client.get_logged_model(model_id).experiment_id
    assert reference.name == f"{NAME}-v{version.version}" and reference.tags[REFERENCE_TAG] == model_id
    assert "bodyschema.model_sha256" not in reference.tags       # never a trust anchor
    found = client.search_logged_models([run.info.experiment_id], filter_string="attributes.model_id IN "
                                        f"({', '.join(repr(i) for i in sorted(ids))})")
    assert [m.model_id for m in found] == [reference.model_id]
    linked = {m.key for m in reference.metrics if m.run_id == run.info.run_id}
    assert linked == set(run.data.metrics) != set()


def test_a_second_evaluation_reuses_the_reference(evaluated, tmp_path):
    client, version, _, run, _ = evaluated
    from bodyschema.evaluation.core.mlflow_log import reference_model, used_models
    from bodyschema.evaluation.core.specs import resolve_model
    tracking = client.tracking_uri
    used = used_models(client, [resolve_model(f"models:/{NAME}/{version.version}", tracking)])
    (model_id, label), = used.items()
    reference = reference_model(client, run.info.experiment_id, model_id, label)
    assert reference != model_id and reference in {m.model_id for m in run.inputs.model_inputs}


def test_the_evaluation_run_lasts_as_long_as_the_benchmark(evaluated):
    *_, run, (t0, t1) = evaluated
    start, end = run.info.start_time / 1000, run.info.end_time / 1000
    assert t0 - 0.01 <= start < end <= t1 + 0.01
    assert end - start >= 0.9 * (t1 - t0) - 0.05, (end - start, t1 - t0)   # not the ~0.5 s of logging alone


def test_experiments_are_described_and_open_in_classic_ml_mode(evaluated):
    client, _, training, run, _ = evaluated
    for experiment_id in (training.info.experiment_id, run.info.experiment_id):
        tags = client.get_experiment(experiment_id).tags
        assert tags[KIND_TAG] == CLASSIC_ML == "custom_model_development"
        assert len(tags[NOTE]) > 40
    assert "Estimation levels" in client.get_experiment(run.info.experiment_id).tags[NOTE]


def test_a_description_edited_in_the_ui_is_kept(workdir):
    import mlflow

    from bodyschema.training.registry import ensure_experiment, use_tracking
    client = use_tracking()
    experiment_id = mlflow.create_experiment("mine", tags={NOTE: "my words"})
    assert ensure_experiment("mine") == experiment_id
    tags = client.get_experiment(experiment_id).tags
    assert tags[NOTE] == "my words" and tags[KIND_TAG] == CLASSIC_ML


def test_the_training_run_holds_its_card_dataset_summary_and_loss_curves(evaluated, kin_store):
    client, version, training, _, _ = evaluated
    run_id = training.info.run_id
    files = {f.path for f in client.list_artifacts(run_id)} | {f.path for f in client.list_artifacts(run_id, "plots")}
    assert {"model_card.md", "dataset_summary.txt", "loss_curves.csv", "plots/loss_curves.png"} <= files
    card = client.download_artifacts(run_id, "model_card.md")
    text = open(card).read()
    assert NAME in text and version.tags["dataset_sha256"] in text and version.tags["val_sha256"] in text
    assert "val_rmse" in text
    summary = open(client.download_artifacts(run_id, "dataset_summary.txt")).read()
    assert str(kin_store) in summary and "ee_xyz" in summary
    rows = open(client.download_artifacts(run_id, "loss_curves.csv")).read().splitlines()
    assert rows[0].startswith("epoch,") and len(rows) == 1 + 3                  # a header and the 3 epochs


def test_the_frames_a_benchmark_scored_are_an_evaluation_input(workdir, kin_store):
    from bodyschema.evaluation.core.mlflow_log import TARGETS_TAG, dataset_inputs
    from bodyschema.training.registry import use_tracking
    digest = load_dataset(kin_store, "ee_xyz").sha256
    (given,) = dataset_inputs(use_tracking(), {}, {f"{TARGETS_TAG}.path": str(kin_store),
                                                    f"{TARGETS_TAG}.sha256": digest})
    assert (given.dataset.name, given.dataset.digest) == (kin_store.name, digest[:32])
    assert {t.key: t.value for t in given.tags} == {"mlflow.data.context": "evaluation", "sha256": digest}
    assert str(kin_store) in given.dataset.source


def test_a_runner_called_directly_is_timed_from_its_model_resolution(workdir):
    from bodyschema.evaluation.levels import run_levels
    config = LevelsConfig(models=("analytic:planar2:ee_xyz",), levels=(1, 2), trials=3, runs=1, multistart=0,
                          plots=False, progress=False, out=workdir / "results" / "levels")
    t0 = time.time()
    summary = run_levels(config)                                     # as the demo calls it: no registry clock
    t1 = time.time()
    info = MlflowClient().get_run(summary.run_id).info
    start, end = info.start_time / 1000, info.end_time / 1000
    assert t0 - 0.01 <= start < end <= t1 + 0.01
    assert end - start >= 0.9 * (t1 - t0) - 0.05, (end - start, t1 - t0)
