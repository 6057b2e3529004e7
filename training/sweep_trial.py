"""One trial of `bodyschema sweep`, run by Ray Tune in a worker process: fit one configuration, as an MLflow run nested
under the sweep's parent run, reporting each epoch to Tune (ASHA stops a bad network early).

The trial is `train`'s fit without its registration: the same dataset split, model construction and held-out score
(`val_rmse` in output units, the champion's criterion), so a sweep's best trial compares with a `train` run as is.
Its run directory is `TrainConfig.run_dir` under the sweep's folder: the model's checkpoint lives there, so a trial
that Tune restarts after a kill resumes its fit from the last epoch and continues the same MLflow child run.
The model is logged (pyfunc, digest tagged) in the child run; only the driver registers, and only the best trial.
"""

from __future__ import annotations

import dataclasses
import inspect
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mlflow
import torch

from bodyschema.training import runs
from bodyschema.training.config import TrainConfig, untrained_model
from bodyschema.training.data import as_float, load_dataset, validation_digest
from bodyschema.training.digest import DIGEST_TAG
from bodyschema.training.pyfunc_loader import log_sensory_model
from bodyschema.training.registry import METRIC, use_tracking
from bodyschema.training.scoring import predict_batched, score

SWEEP_TAG = "bodyschema.sweep"           # on the parent and its children: the sweep folder's name
FINAL = "val_rmse_final"                 # only a trial that ran to its end reports it (ASHA stops the others)
EPOCH = "epoch"                          # ASHA's time attribute: 1-based epochs, true across a resumed fit


@dataclass(frozen=True)
class TrialContext:
    """What every trial shares (sent once to the workers with `tune.with_parameters`)."""

    train: TrainConfig                   # the sweep's fixed settings; its model config holds the fixed hyper-values
    tracking_uri: str                    # resolved: a worker's cwd is not the driver's
    experiment_id: str
    parent_run_id: str
    sweep_name: str
    reports_epochs: bool                 # a network reports every epoch; a GP once, at the end


def trial_config(context: TrialContext, hyper: dict[str, Any]) -> TrainConfig:
    """The TrainConfig of one trial: the sweep's config with the trial's hyper-parameters."""
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in hyper.items()}   # Tune's JSON turns tuples to lists
    return dataclasses.replace(context.train, model=dataclasses.replace(context.train.model, **values),
                               tracking_uri=context.tracking_uri)


def run_trial(hyper: dict[str, Any], context: TrialContext) -> None:
    """Tune's function trainable: fit, report, score, log the model in a nested run."""
    import ray
    from ray import tune

    config = trial_config(context, hyper)
    if ray.get_gpu_ids():                    # Tune gave this trial a GPU (resources per trial): train on it
        config = dataclasses.replace(config, device="cuda")
    client = use_tracking(config.tracking_uri)
    data = load_dataset(config.data, config.modalities, val_fraction=config.val_fraction, seed=config.seed,
                        max_train=config.max_train)
    model = untrained_model(config, data.body, {config.modality: data.output_shape(config.modality)})
    run_dir = config.run_dir(data.sha256)
    run_dir.mkdir(parents=True, exist_ok=True)
    child = runs.marked_run(client, run_dir)
    start = (dict(run_id=child.info.run_id) if child is not None else
             dict(experiment_id=context.experiment_id, parent_run_id=context.parent_run_id,
                  run_name=f"{config.kind} · {_short(hyper)}", tags={SWEEP_TAG: context.sweep_name}))
    with mlflow.start_run(**start) as run:
        (run_dir / runs.MARKER).write_text(run.info.run_id)
        if child is None:
            mlflow.log_params({f"hyper.{k}": str(v) for k, v in config.hyper_values().items()})
        base = {"child_run_id": run.info.run_id}
        epochs = getattr(config.model, "epochs", 0)
        last: dict[str, float] = {}      # the final report repeats the last epoch's: Tune wants ASHA's metric in all

        def on_epoch(epoch: int, metrics: dict[str, float]) -> None:
            numbers = {k: float(v) for k, v in metrics.items()}
            mlflow.log_metrics(numbers, step=int(epoch), synchronous=False)
            if context.reports_epochs:
                last.update(numbers, **{EPOCH: int(epoch) + 1})
                if last[EPOCH] < epochs:     # the last epoch is reported with the score: ASHA never cuts a done fit
                    tune.report({**base, **last})

        fit = dict(seed=config.seed, val=(data.val.q, data.val.x), on_epoch=on_epoch, progress=False)
        accepts = inspect.signature(model.fit).parameters           # as `train`: only the kinds that take them
        if "checkpoint" in accepts:
            fit["checkpoint"] = run_dir / "checkpoint.pt"
        if "device" in accepts:
            fit["device"] = config.device
        model.fit(data.train.q, data.train.x, **fit)
        dtype = torch.float32 if data.is_image(config.modality) else torch.float64   # as `train` scores
        scores = score(predict_batched(model, data.val.q, dtype=dtype), as_float(data.val.x).numpy(), "val")
        mlflow.log_metrics(scores)
        model_dir = run_dir / "model"
        shutil.rmtree(model_dir, ignore_errors=True)              # stale files would change the digest
        model.save(model_dir)
        info, digest = log_sensory_model(model_dir, model)
        mlflow.set_tag(DIGEST_TAG, digest)
    # After the child run has ended: a stop that Tune sends on this last report must not leave it RUNNING.
    tune.report({**base, **last, **scores, "model_uri": info.model_uri, "digest": digest,
                 "dataset_sha256": data.sha256, "val_sha256": validation_digest(data),
                 "dataset": str(Path(data.path).resolve()), "robot": data.body.robot,
                 "joint_names": ",".join(data.body.joint_names), "mjcf_sha256": str(data.attrs.get("mjcf_sha256", "")),
                 FINAL: scores[METRIC]})


def _short(hyper: dict[str, Any]) -> str:
    """The trial's run name: its swept values, e.g. "lr=0.001 channels=16x8"."""
    def word(v):
        return "x".join(map(str, v)) if isinstance(v, (list, tuple)) else f"{v:.3g}" if isinstance(v, float) else v
    return " ".join(f"{k}={word(v)}" for k, v in sorted(hyper.items()))
