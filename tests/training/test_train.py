"""`train` end to end on the default embedded store: what a run logs, resume after a kill, failure leaves no trace."""

import json

import mlflow
import numpy as np
import pytest
import torch
from mlflow import MlflowClient

from bodyschema.training.data import load_dataset
from bodyschema.training.digest import DIGEST_TAG, directory_sha256
from bodyschema.training.registry import load
from bodyschema.training.scoring import _subset
from bodyschema.training.train import train
from tests.training.tiny_model import Boom, tiny_config


def _client(workdir):
    return MlflowClient(f"sqlite:///{workdir / 'mlflow.db'}")


def test_a_run_logs_config_epochs_dataset_versions_plots_and_registers(workdir, kin_store, tiny_kind):
    result = train(tiny_config(kin_store, epochs=12))
    client = _client(workdir)
    run = client.get_run(result.run_id)
    data = load_dataset(kin_store, "ee_xyz")

    assert run.info.status == "FINISHED"
    assert run.data.params["model"] == "tiny" and run.data.params["hyper.epochs"] == "12"
    assert run.data.params["seed"] == "0" and run.data.params["n_val"] == str(len(data.val))
    assert [m.step for m in client.get_metric_history(result.run_id, "train_loss")] == list(range(12))
    assert run.data.metrics["val_rmse"] == pytest.approx(result.metrics["val_rmse"])
    (dataset_input,) = run.inputs.dataset_inputs
    assert dataset_input.dataset.digest == data.sha256[:32] and dataset_input.dataset.name == "kin.zarr"
    assert run.data.tags["robot"] == "planar2" and run.data.tags["mjcf_sha256"] == data.attrs["mjcf_sha256"]
    assert run.data.tags["version.torch"] == torch.__version__ and run.data.tags["version.mlflow"] == mlflow.__version__
    logged = {f.path for f in client.list_artifacts(result.run_id, "plots")}
    assert logged == {"plots/loss_curves.png", "plots/val_scatter.png"}
    assert all(p.stat().st_size > 1000 for p in result.plots.values())
    assert (workdir / "mlartifacts").is_dir(), "artifacts go under the working directory"

    assert result.registered_name == "bodyschema-planar2-ee_xyz-tiny" and result.model_version == "1"
    assert result.champion
    assert f"registered models:/{result.registered_name}/1  → now @champion" in str(result)
    version = client.get_model_version(result.registered_name, "1")
    assert version.tags[DIGEST_TAG] == directory_sha256(result.model_dir) == run.data.tags[DIGEST_TAG]
    assert float(version.tags["val_rmse"]) == result.metrics["val_rmse"]

    model = load("models:/bodyschema-planar2-ee_xyz-tiny@champion")
    z = torch.as_tensor(data.val.q[:16], dtype=torch.float64)
    from bodyschema.models import load_model
    saved = load_model(result.model_dir)
    torch.testing.assert_close(model.predict(z), saved.predict(z), rtol=0, atol=0)
    assert model.jacobian(z).shape == (16, 3, 2) and model.precision(z).shape == (16, 3)
    # The val metric is what the model really scores on the held-out rows.
    pred = model.predict(torch.as_tensor(data.val.q)).numpy()
    assert np.sqrt(np.mean((pred - data.val.x) ** 2)) == pytest.approx(result.metrics["val_rmse"], rel=1e-5)
    # The pyfunc flavour (for generic MLflow consumers) predicts the same g(z).
    pyfunc = mlflow.pyfunc.load_model(f"models:/{result.registered_name}/{result.model_version}")
    np.testing.assert_allclose(pyfunc.predict(z.numpy()), model.predict(z).numpy(), rtol=0, atol=0)


def test_killed_run_resumes_its_checkpoint_and_its_mlflow_run(workdir, kin_store, tiny_kind, monkeypatch):
    config = tiny_config(kin_store, epochs=20)
    monkeypatch.setattr(tiny_kind, "fail_at", 7)
    monkeypatch.setattr(tiny_kind, "fail_with", "interrupt")
    with pytest.raises(KeyboardInterrupt):
        train(config)
    client = _client(workdir)
    (run_dir,) = (workdir / "runs").iterdir()
    first_id = (run_dir / "mlflow_run_id").read_text()
    assert client.get_run(first_id).info.status == "KILLED"
    assert not client.search_registered_models(), "an interrupted run registers nothing"

    monkeypatch.setattr(tiny_kind, "fail_at", -1)
    resumed = train(config)
    assert resumed.run_id == first_id and client.get_run(first_id).info.status == "FINISHED"
    steps = [m.step for m in client.get_metric_history(first_id, "train_loss")]
    assert steps == list(range(20)), "each epoch ran exactly once over the two attempts"
    lines = (run_dir / "history.jsonl").read_text().splitlines()
    assert [json.loads(line)["epoch"] for line in lines] == list(range(20))

    # Same weights as an uninterrupted run of the same config.
    fresh = train(tiny_config(kin_store, epochs=20, run_root=workdir / "fresh", register=False))
    assert directory_sha256(fresh.model_dir) == directory_sha256(resumed.model_dir)


def test_a_failed_fit_ends_failed_registers_nothing_and_keeps_the_champion(workdir, kin_store, tiny_kind,
                                                                           monkeypatch):
    good = train(tiny_config(kin_store, epochs=5))
    monkeypatch.setattr(tiny_kind, "fail_at", 2)
    with pytest.raises(Boom):
        train(tiny_config(kin_store, epochs=40))
    client = _client(workdir)
    runs = client.search_runs([client.get_experiment_by_name("bodyschema").experiment_id])
    assert sorted(r.info.status for r in runs) == ["FAILED", "FINISHED"]
    versions = client.search_model_versions(f"name = '{good.registered_name}'")
    assert [str(v.version) for v in versions] == ["1"]
    assert str(client.get_model_version_by_alias(good.registered_name, "champion").version) == "1"

    # Started again once fixed, the config gets a new run (the FAILED one stays FAILED), from the checkpoint.
    monkeypatch.setattr(tiny_kind, "fail_at", -1)
    again = train(tiny_config(kin_store, epochs=40))
    failed = next(r for r in runs if r.info.status == "FAILED")
    assert again.run_id != failed.info.run_id and client.get_run(failed.info.run_id).info.status == "FAILED"
    assert [m.step for m in client.get_metric_history(again.run_id, "train_loss")] == list(range(3, 40))


def test_image_run_logs_a_target_vs_prediction_grid(workdir, image_store, tiny_kind):
    result = train(tiny_config(image_store, modality="image", epochs=3, register=False))
    assert set(result.plots) == {"loss_curves", "val_images"} and result.registered_name is None
    assert 0 < result.metrics["val_rmse"] < 1, "image errors are in [0, 1] intensity units"
    logged = {f.path for f in _client(workdir).list_artifacts(result.run_id, "plots")}
    assert "plots/val_images.png" in logged


def test_training_score_subset_keeps_rows_aligned(kin_store):
    split = load_dataset(kin_store, "ee_xyz").train
    sub = _subset(split, 7, seed=0)
    assert len(sub) == 7 and set(sub.rows) <= set(split.rows)
    index = {row: i for i, row in enumerate(split.rows)}
    np.testing.assert_array_equal(sub.xs["ee_xyz"], split.x[[index[r] for r in sub.rows]])
    np.testing.assert_array_equal(sub.q, split.q[[index[r] for r in sub.rows]])


def test_an_image_encoder_is_scored_in_joint_degrees_registered_and_loaded_back(workdir, image_store):
    from bodyschema.models.configs import EncoderConfig
    from bodyschema.models.encoder import ImageEncoder
    from bodyschema.training.config import TrainConfig

    hyper = EncoderConfig(epochs=3, channels=(8, 8), fc_hidden=16)
    result = train(TrainConfig(model=hyper, data=image_store, progress=False))
    data = load_dataset(image_store, "image")
    assert result.registered_name == "bodyschema-planar2-image-encoder" and result.champion
    assert set(result.plots) == {"loss_curves", "val_joints"}
    encoder = load(f"models:/{result.registered_name}@champion", expect_body=data.body, expect_modality="image")
    assert isinstance(encoder, ImageEncoder) and encoder.image_shape == (16, 16)
    err = np.degrees(encoder.encode(data.val.x).numpy()) - np.degrees(data.val.q)   # (N, 2) deg
    assert np.sqrt(np.mean(err ** 2)) == pytest.approx(result.metrics["val_rmse"], rel=1e-5)
    for name, e in zip(data.body.joint_names, np.abs(err).mean(axis=0)):   # each joint's mean |error|, printed in deg
        assert result.metrics[f"val_abs_error.{name}"] == pytest.approx(e, rel=1e-5)
        assert f"val_abs_error.{name}={result.metrics[f'val_abs_error.{name}']:.4g} deg" in str(result)
    version = _client(workdir).get_model_version(result.registered_name, result.model_version)
    assert float(version.tags["val_rmse"]) == result.metrics["val_rmse"], "the champion is chosen in degrees"


def test_device_is_checked_at_the_config_and_left_out_of_the_run_identity(kin_store, tiny_kind, monkeypatch):
    from bodyschema.models.configs import PixelConfig
    from bodyschema.training.config import TrainConfig

    config = tiny_config(kin_store)
    assert config.device == "cpu" and "device" not in config.identity("sha")
    with pytest.raises(ValueError, match=r"device must be .*Got 'gpu'"):
        tiny_config(kin_store, device="gpu")
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match=r"device must be 'cpu' or an available CUDA device. Got 'cuda'. CUDA "
                                             r"is not available on this machine: use --device cpu"):
            TrainConfig(model=PixelConfig(), data=kin_store, device="cuda")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)     # a one-GPU machine, as far as checks go
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(ValueError, match=r"Got 'cuda:1'. This machine has 1 CUDA device"):
        tiny_config(kin_store, device="cuda:1")
    gpu = tiny_config(kin_store, device="cuda:0")
    assert gpu.config_hash("sha") == config.config_hash("sha"), "the device is not part of a run's identity"


def test_a_kind_without_device_support_refuses_cuda_before_any_run(workdir, kin_store, tiny_kind, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(ValueError, match=r"device must be 'cpu' for model kind 'tiny'. Got 'cuda'"):
        train(tiny_config(kin_store, device="cuda"))
    assert not (workdir / "runs").exists(), "refused before a run directory or MLflow run exists"
    with pytest.raises(ValueError, match=r"mixed_precision must be false for model kind 'tiny'. Got True"):
        train(tiny_config(kin_store, mixed_precision=True))
    assert not (workdir / "runs").exists()


def test_val_rmse_has_one_name_and_one_meaning(workdir, kin_store, tiny_kind):
    """MLflow holds one `val_rmse` (the held-out score after the fit, no `fit_val_rmse` beside it), and a GP's own
    report of it during the fit means the same: RMSE over all output elements, as `score` computes it."""
    from bodyschema.models.gpr import GPRModel
    from bodyschema.training.scoring import score

    result = train(tiny_config(kin_store, epochs=5))                 # the tiny kind reports val_rmse every epoch
    client = _client(workdir)
    assert not [k for k in client.get_run(result.run_id).data.metrics if k.startswith("fit_val")]
    (logged,) = client.get_metric_history(result.run_id, "val_rmse")
    assert logged.value == pytest.approx(result.metrics["val_rmse"])

    data = load_dataset(kin_store, "ee_xyz", max_train=200)
    reports = []
    gp = GPRModel(data.body, "ee_xyz", (3,), adam_steps=5, lbfgs_steps=0)
    gp.fit(data.train.q, data.train.x, val=(data.val.q, data.val.x), on_epoch=lambda step, m: reports.append(m),
           progress=False)
    # float64 in, so float64 out: the errors (~8 µm) are within 1e-6 of a float32 prediction's rounding (~30 nm)
    pred = gp.predict(torch.as_tensor(data.val.q, dtype=torch.float64)).numpy()
    expected = score(pred, data.val.x, "val")
    assert reports[-1]["val_rmse"] == pytest.approx(expected["val_rmse"], rel=1e-6)
    assert reports[-1]["val_mean_error"] == pytest.approx(expected["val_mean_error"], rel=1e-6)


def test_svgp_trains_through_train_and_refuses_mixed_precision(workdir, kin_store):
    # svgp's fit takes a device but has no bf16: train passes each only where the kind's fit takes it
    from bodyschema.models.configs import SVGPConfig
    from bodyschema.training.config import TrainConfig

    small = SVGPConfig(num_inducing=16, hyper_points=40)
    with pytest.raises(ValueError, match=r"mixed_precision must be false for model kind 'svgp'. Got True"):
        train(TrainConfig(model=small, data=kin_store, modality="ee_xyz", progress=False, mixed_precision=True))
    result = train(TrainConfig(model=small, data=kin_store, modality="ee_xyz", progress=False))
    assert result.metrics["val_rmse"] < 0.05                            # m: a 2-link arm, 16 inducing points


def test_per_joint_scores_name_every_joint_with_characters_mlflow_accepts():
    from bodyschema.training.scoring import per_joint

    pred, target = np.array([[1.0, -2.0], [3.0, 2.0]]), np.zeros((2, 2))
    scores = per_joint(pred, target, ["arm/elbow:1", "wrist roll"])
    assert scores == {"val_abs_error.arm_elbow_1": 2.0, "val_abs_error.wrist roll": 2.0}


def test_a_model_perceived_at_its_sensors_precision_is_warned_when_it_errs_like_the_sensor(kin_store):
    from bodyschema.models.analytic import AnalyticModel
    from bodyschema.models.gpr import GPRModel
    from bodyschema.training.scoring import score, sensor_warning

    data = load_dataset(kin_store, "ee_xyz", max_train=200)
    gp = GPRModel(data.body, "ee_xyz", (3,)).fit(data.train.q, data.train.x, progress=False)
    pred = gp.predict(torch.as_tensor(data.val.q, dtype=torch.float64)).numpy()
    assert sensor_warning(gp, score(pred, data.val.x, "val")) is None            # µm off, the sensor's σ is 1 mm
    off = score(pred + 0.5e-3, data.val.x, "val")                               # 0.5 mm off in every coordinate
    warning = sensor_warning(gp, off)
    assert warning.startswith("gpr of ee_xyz: held-out RMSE must be at most 0.25 × the sensor's σ = 0.001 m")
    assert "Got '0.0005 m (0.50 σ)'" in warning and "3^D" in warning
    assert sensor_warning(AnalyticModel("planar2", "ee_xyz"), off) is None      # exact: perceived at its own Π
