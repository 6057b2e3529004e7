"""`train(config)`: dataset → fit → validation metrics, plots → MLflow run → registered model (maybe champion).

One call is one MLflow run. Steps: resolve tracking; load, validate and split the dataset; build the model
from the kind table; fit it with a checkpoint in `<run_root>/<kind>-<modality>-<config hash>/` (a killed run
started again with the same config resumes there, and continues the same MLflow run); score it on the
held-out split (`val_rmse` in output units decides the champion; joint degrees for an image encoder, kind
"encoder", registered as `bodyschema-{robot}-image-encoder`); save, plot, log, register.
An exception anywhere before registration ends the run FAILED and registers nothing; Ctrl-C ends it KILLED.
A multimodal model registers one SensoryModel per modality, `bodyschema-{robot}-{modality}-multimodal`.
Each step's seconds are a debug line (`--verbose`); called from Python, it prints nothing (progress off by default,
MLflow quiet).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import logging
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import mlflow
from mlflow.exceptions import MlflowException

from bodyschema import log
from bodyschema.base import modalities
from bodyschema.errors import must_be
from bodyschema.training import guards, plots, run_record, run_summary, runs, scoring
from bodyschema.training.champion import CHAMPION, register_version
from bodyschema.training.config import TrainConfig, untrained_model
from bodyschema.training.data import Dataset, load_dataset, validation_digest
from bodyschema.training.digest import DIGEST_TAG
from bodyschema.training.model_card import card_markdown, score_unit, with_unit
from bodyschema.training.pyfunc_loader import log_sensory_model
from bodyschema.training.registry import (
    DATASET_TAG,
    METRIC,
    VAL_TAG,
    ensure_experiment,
    registered_name,
    use_tracking,
)

FINAL_METRICS = ("val_rmse", "val_mean_error", "train_rmse", "train_mean_error", "fit_seconds")
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Registered:
    modality: str
    name: str                        # bodyschema-{robot}-{modality}-{kind}
    version: str
    champion: bool                   # True when this version now holds the `champion` alias
    model_sha256: str


@dataclass(frozen=True)
class TrainResult:
    run_id: str
    registered: tuple[Registered, ...]  # one per modality (several for multimodal); empty when not registering
    metrics: dict[str, float]        # val_rmse, val_mean_error, train_rmse, fit_seconds, last epoch's metrics
    plots: dict[str, Path] = field(default_factory=dict)
    model_dirs: dict[str, Path] = field(default_factory=dict)   # modality -> saved model (meta.json + state.pt)
    run_dir: Path | None = None      # checkpoint, history, plots of this config
    reused: bool = False             # True: this config had finished and registered already; nothing was redone
    # The unit of each score, by its key's prefix ("" or "<modality>/"): the model's output unit, deg for an encoder
    units: dict[str, str] = field(default_factory=dict)

    # Single-modality shortcuts (None when nothing, or several models, were registered).
    @property
    def registered_name(self) -> str | None:
        return self.registered[0].name if len(self.registered) == 1 else None

    @property
    def model_version(self) -> str | None:
        return self.registered[0].version if len(self.registered) == 1 else None

    @property
    def champion(self) -> bool:
        return len(self.registered) == 1 and self.registered[0].champion

    @property
    def model_dir(self) -> Path | None:
        return next(iter(self.model_dirs.values())) if len(self.model_dirs) == 1 else None

    def __str__(self) -> str:
        """What `bodyschema train` prints: the run, each registered version, the held-out scores, the plots."""
        lines = [f"MLflow run {self.run_id} (run directory {self.run_dir})"]
        if self.reused:
            lines[0] += ": finished before with this config; reusing its registered versions"
        for r in self.registered:
            lines.append(f"registered models:/{r.name}/{r.version}" + (
                "  → now @champion" if r.champion else
                "  (champion unchanged: not better, or the champion was scored on other validation data)"))
        scores = {k: v for k, v in self.metrics.items() if "val_" in k and not k.startswith("fit_")}
        if "val_loss" in scores and "best_loss" in self.metrics:    # the kept weights' epoch, not the last one's
            scores["val_loss"] = self.metrics["best_loss"]
        lines.append("held-out: " + ", ".join(f"{k}={v:.4g}{self._unit(k)}" for k, v in sorted(scores.items())))
        lines += [f"plot: {p}" for p in self.plots.values()]
        return "\n".join(lines)

    def _unit(self, key: str) -> str:
        """" <unit>" of the score `key` ("val_rmse" or "<modality>/val_rmse"), or "" where none is known or applies."""
        return with_unit(key, self.units.get(key[:key.rfind("/") + 1], ""))


def train(config: TrainConfig) -> TrainResult:
    """Train, evaluate, log and (unless `config.register` is False) register one model. See the module doc."""
    with log.quiet_mlflow():
        return _train(config)


def _train(config: TrainConfig) -> TrainResult:
    guards.check_config(config.kind, config.modalities)           # a GP on images: refused before any work
    with log.timed(_log, "tracking store opened"):
        client = use_tracking(config.tracking_uri)
    with log.timed(_log, f"data read from {config.data}"):
        data = load_dataset(config.data, config.modalities, val_fraction=config.val_fraction, seed=config.seed,
                            max_train=config.max_train, progress=config.progress)
    _log.debug("data: %s, sha256 %s…; split by %s: %d train rows (max_train %s), %d validation rows",
               ", ".join(data.modalities), data.sha256[:16], data.split_by, len(data.train), config.max_train,
               len(data.val))
    shapes = {m: data.output_shape(m) for m in data.modalities}
    model = untrained_model(config, data.body, shapes)
    fit_parameters = inspect.signature(model.fit).parameters
    on_device = "device" in fit_parameters                       # the network kinds (and svgp) train on a GPU
    if config.device != "cpu" and not on_device:
        raise ValueError(must_be("device", f"'cpu' for model kind {config.kind!r}", config.device,
                                 "Only the network kinds (pixel, encoder) train on CUDA."))
    if config.mixed_precision and "mixed_precision" not in fit_parameters:
        raise ValueError(must_be("mixed_precision", f"false for model kind {config.kind!r}", True,
                                 "Only the network kinds (pixel, encoder) train in bf16."))
    for shape in shapes.values():                                 # GP memory (n², outputs) vs available RAM
        guards.check_memory(config.kind, model, len(data.train), shape)
    multi = model.has_members                      # MultimodalModel: one SensoryModel per modality
    members = dict(model.members) if multi else {config.modality: model}
    run_dir = config.run_dir(data.sha256)
    with runs.claim(run_dir):      # one process per config: the same command started twice is refused, naming the pid
        return _train_owned(config, client, data, model, members, multi, run_dir, on_device)


def _train_owned(config: TrainConfig, client, data: Dataset, model, members: dict, multi: bool, run_dir: Path,
                 on_device: bool) -> TrainResult:
    """`train` once this process owns `run_dir`: reuse a finished run, or continue / start one and fit."""
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(config.identity(data.sha256), indent=2, default=str))
    experiment_id = ensure_experiment(config.experiment)
    identity = config.config_hash(data.sha256)
    units = {(f"{m}/" if multi else ""): score_unit(member) for m, member in members.items()}
    done = runs.finished_run(client, run_dir, identity, experiment_id, tuple(members), config.register)
    if done is not None:                            # re-run of a finished command: no second version
        _log.debug("run %s finished before with this config: reused", done[0].info.run_id)
        return dataclasses.replace(_reused(client, *done, run_dir, multi), units=units)
    runs.reap_dead_runs(client, experiment_id)      # RUNNING runs whose process died (kill -9) become KILLED
    resume_id = runs.resumable_run(client, run_dir)
    history = run_record.History(run_dir / "history.jsonl")

    start = dict(run_id=resume_id) if resume_id else dict(experiment_id=experiment_id, run_name=run_dir.name)
    with mlflow.start_run(**start, tags=runs.owner_tags(identity)) as run:   # an exception inside ends it FAILED
        (run_dir / "mlflow_run_id").write_text(run.info.run_id)
        params = run_record.log_inputs(config, data, run_dir.name)

        def on_epoch(epoch: int, metrics: dict[str, float]) -> None:
            history.add(epoch, metrics)
            if _log.isEnabledFor(logging.DEBUG):
                _log.debug("epoch %d at %.2f s: %s", epoch, time.perf_counter() - t0,
                           ", ".join(f"{k}={v:.4g}" for k, v in metrics.items()))
            # One name, one meaning: val_rmse & co. are logged once, by `scoring.score` after the fit (the champion's
            # criterion); a model's own report of them during the fit stays in history.jsonl (the loss curves).
            during = {k: float(v) for k, v in metrics.items() if k.split("/")[-1] not in FINAL_METRICS}
            if during:
                mlflow.log_metrics(during, step=int(epoch), synchronous=False)

        train_x = data.train.xs if multi else data.train.x
        val = (data.val.q, data.val.xs if multi else data.val.x)
        fit_kwargs = dict(seed=config.seed, val=val, on_epoch=on_epoch, progress=config.progress)
        if "checkpoint" in inspect.signature(model.fit).parameters:
            fit_kwargs["checkpoint"] = run_dir / "checkpoint.pt"
        if on_device:
            fit_kwargs["device"] = config.device
        if config.mixed_precision:
            fit_kwargs["mixed_precision"] = True
        t0 = time.perf_counter()
        try:
            model.fit(data.train.q, train_x, **fit_kwargs)
        except KeyboardInterrupt:
            mlflow.end_run("KILLED")         # not FAILED: the same config started again continues this run
            raise
        metrics = {"fit_seconds": time.perf_counter() - t0}
        _log.debug("fit (%s on %d rows): %.2f s", config.kind, len(data.train), metrics["fit_seconds"])

        made = {}
        title = plots.run_title(config.kind, data.modalities, data.body.robot)      # not the run hash
        curves = plots.loss_curves(history.epochs, run_dir / "plots" / "loss_curves.png", title,
                                   unit=modalities.unit(config.modality, "output units"))
        if curves is not None:
            made["loss_curves"] = curves
        model_dirs = {}
        for m, member in members.items():
            prefix = f"{m}/" if multi else ""
            with log.timed(_log, f"{m}: scored and plotted"):
                scores, plot = scoring.score_and_plot(member, data, m, config.seed, run_dir / "plots", prefix,
                                               config.progress, plots.run_title(config.kind, m, data.body.robot))
            metrics.update({prefix + k: v for k, v in scores.items()})
            if warning := scoring.sensor_warning(member, scores):
                _log.warning(warning)
            made.update(plot)
            model_dirs[m] = run_dir / ("model" if not multi else f"model-{m}")
            shutil.rmtree(model_dirs[m], ignore_errors=True)    # stale files would change the digest
            member.save(model_dirs[m])
        with log.timed(_log, "metrics and plots logged"):   # and the loss curves, dataset summary
            mlflow.log_metrics(metrics)
            for path in made.values():
                mlflow.log_artifact(str(path), artifact_path="plots")
            run_record.log_run_files(data, history, run_dir)

        registered, cards = [], []                       # registration last: a failure above registers nothing
        for m, member in members.items():
            prefix = f"{m}/" if multi else ""
            with log.timed(_log, f"{m}: model logged" + (" and registered" if config.register else "")):
                entry = _log_and_register(client, member, model_dirs[m], config, data, metrics, prefix, params,
                                          multi, cards)
            if entry is not None:
                registered.append(entry)
        mlflow.set_tag("bodyschema.champion", ",".join(r.name for r in registered if r.champion) or "none")
        run_summary.write(run_dir, cards, registered, made)
    return TrainResult(run.info.run_id, tuple(registered), {**history.last(), **metrics}, made, model_dirs, run_dir,
                       units=units)


def _log_and_register(client, member, model_dir: Path, config: TrainConfig, data: Dataset, metrics: dict[str, float],
                      prefix: str, params: dict, multi: bool, cards: list[str]) -> Registered | None:
    """Log one member as a pyfunc and its model card (`model_card[-<modality>].md`, also appended to `cards`);
    register it (unless config.register is False) and maybe make it champion."""
    m, val_rmse = member.modality, metrics[prefix + METRIC]
    name = registered_name(data.body.robot, m, config.kind) if config.register else None
    info, digest = log_sensory_model(model_dir, member, name=f"model-{m}" if multi else "model")
    mlflow.set_tag(DIGEST_TAG + (f".{m}" if multi else ""), digest)
    tags = {DIGEST_TAG: digest, METRIC: repr(val_rmse), "robot": data.body.robot, "modality": m,
            "kind": config.kind, "joint_names": ",".join(data.body.joint_names),
            "dataset_sha256": data.sha256, "mjcf_sha256": str(data.attrs.get("mjcf_sha256", "")),
            VAL_TAG: validation_digest(data), DATASET_TAG: str(Path(data.path).resolve())}
    scores = {k[len(prefix):]: v for k, v in metrics.items() if k.startswith(prefix) and "/" not in k[len(prefix):]}
    card = card_markdown(member, name, tags, scores, params)
    mlflow.log_text(card, f"model_card{'-' + m if multi else ''}.md")
    cards.append(card)
    if name is None:
        return None
    version, champion = register_version(client, name, info.model_uri, tags, val_rmse)   # one guarded step
    _log.debug("registered %s v%s (%s=%.4g): %s", name, version, METRIC, val_rmse,
               "now @champion" if champion else "champion unchanged")
    return Registered(m, name, version, champion, digest)


def _reused(client, run, versions: dict, run_dir: Path, multi: bool) -> TrainResult:
    """The result of a finished run of the same config, from the tracking database (nothing is redone)."""
    registered = []
    for m, v in versions.items():
        try:
            champion = str(client.get_model_version_by_alias(v.name, CHAMPION).version) == str(v.version)
        except MlflowException:
            champion = False
        registered.append(Registered(m, v.name, str(v.version), champion, v.tags[DIGEST_TAG]))
    metrics = {**run_record.History(run_dir / "history.jsonl").last(), **run.data.metrics}
    model_dirs = {m: run_dir / (f"model-{m}" if multi else "model") for m in versions}
    made = {p.stem: p for p in sorted((run_dir / "plots").glob("*.png"))}
    return TrainResult(run.info.run_id, tuple(registered), metrics, made, model_dirs, run_dir, reused=True)
