"""`bodyschema sweep KIND`: a grid or random search over a model kind's hyper-parameters on Ray Tune.

One sweep is one MLflow parent run, `sweep · KIND · robot`, with one nested child run per trial (its params and
per-epoch metrics, sweep_trial.py); the parent logs the table of trials. Networks report every epoch and ASHA stops
the bad ones early; a GP reports once, at the end, so it runs to completion (no early stop). The best finished trial
(lowest `val_rmse`, the champion's criterion) is registered as a new version; `@champion` moves only if it beats the
current one (`champion.register_version`, the very comparison `train` makes).

Ray is the datagen backend's (`ray_session`): a local loopback-only Ray, or the cluster RAY_ADDRESS names (checked
within a timeout). Trials get 1 CPU each, and 1 GPU each when the cluster has GPUs. The sweep folder
`<run_root>/sweeps/<kind>-<modality>-<hash of the sweep>` holds Tune's experiment and every trial's checkpoint: the
same command run again after a kill restores the experiment (`Tuner.restore`) and continues the same parent run;
an unfinished trial resumes its fit from its last epoch. Everything is checked before Ray starts or a run is made.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import logging
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import mlflow

from bodyschema import log
from bodyschema.base.ray_session import ray_session
from bodyschema.errors import must_be
from bodyschema.models import kinds
from bodyschema.training import guards, sweep_report
from bodyschema.training.config import TrainConfig, untrained_model
from bodyschema.training.data import load_dataset
from bodyschema.training.registry import ensure_experiment, sqlite_path, tracking_uri, use_tracking
from bodyschema.training.sweep_config import SweepConfig
from bodyschema.training.sweep_probe import estimate
from bodyschema.training.sweep_space import SearchSpace, parse_space
from bodyschema.training.sweep_trial import EPOCH, SWEEP_TAG, TrialContext, run_trial

PARENT_MARKER = "parent_run_id"      # in the sweep folder: the parent run a re-run continues
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Plan:
    """A checked sweep: what `sweep` runs, decided before Ray starts or any run is made."""

    config: SweepConfig
    space: SearchSpace
    train: TrainConfig                   # fixed settings of every trial (register off: the driver registers)
    network: bool                        # reports every epoch (ASHA) or once (a GP)
    max_epochs: int | None
    concurrent: int


def plan(config: SweepConfig) -> Plan:
    """Every check on the input (the house error, all problems of the search space at once); no side effects."""
    try:
        kind = kinds.get(config.kind)
    except ValueError as error:
        raise ValueError(must_be("KIND", f"a trainable model kind: one of {_sweepable()}", config.kind)) from error
    if not kinds.model_class(kind.name).sweepable:
        raise ValueError(must_be("KIND", f"one of {_sweepable()}", kind.name, f"Train {kind.name} with `bodyschema "
                                 "train` (it is scored otherwise than by one decoder's val_rmse)."))
    cls = kind.config_class
    space = parse_space(cls, kind.name, config.grid, config.space, config.random)
    losses = [d.grid for d in space.dimensions if d.name == "loss"]
    if losses and len(set(losses[0])) > 1:
        raise ValueError(must_be("--grid loss", "one value", ", ".join(map(str, losses[0])),
                                 "ASHA compares trials by their val_loss, which differs in kind between losses: "
                                 "sweep one loss at a time."))
    fixed = {}
    if config.epochs_budget is not None:
        if "epochs" not in {f.name for f in dataclasses.fields(cls)} or "epochs" in space.describe():
            raise ValueError(must_be("--epochs-budget", f"given for a kind with epochs, not swept ({kind.name})",
                                     config.epochs_budget, "Sweep epochs with --grid, or drop --epochs-budget."))
        fixed["epochs"] = config.epochs_budget
    train = TrainConfig(model=cls(**fixed), data=Path(config.data).resolve(), modality=config.modality,
                        seed=config.seed, val_fraction=config.val_fraction, max_train=config.max_train,
                        experiment=config.experiment, tracking_uri=config.tracking_uri, register=False,
                        run_root=Path(config.run_root).resolve() / "sweeps", progress=False)
    network = bool(getattr(kinds.model_class(kind.name), "network", False))
    epochs = [d.high if not d.grid else max(d.grid) for d in space.dimensions if d.name == "epochs"]
    max_epochs = int(max(epochs)) if epochs else getattr(train.model, "epochs", None)
    cpus = os.cpu_count() or 1
    concurrent = min(space.trials, cpus) if config.max_concurrent is None else config.max_concurrent
    if concurrent < 1 or (not os.environ.get("RAY_ADDRESS") and concurrent > cpus):
        raise ValueError(must_be("--max-concurrent", f"between 1 and this machine's {cpus} CPUs", concurrent,
                                 "Each trial takes one CPU; more would only queue."))
    return Plan(config, space, train, network, max_epochs, concurrent)


def sweep(config: SweepConfig) -> sweep_report.SweepResult:
    """Run the sweep `config` describes (see the module doc) and return its trials and registration."""
    with log.quiet_mlflow():
        return _sweep(plan(config))


def _sweep(p: Plan) -> sweep_report.SweepResult:
    client = use_tracking(p.config.tracking_uri)
    uri = _absolute(tracking_uri(p.config.tracking_uri))            # a trial's cwd is its trial folder
    data = load_dataset(p.train.data, p.train.modalities, val_fraction=p.train.val_fraction, seed=p.train.seed,
                        max_train=p.train.max_train)
    check_memory(p, data)                                           # every trial's fit, as `train` checks one
    with ray_session(os.cpu_count() or 1) as ray:                   # RAY_ADDRESS unreachable: refused here
        cpus, gpus = ray.cluster_resources().get("CPU", 0), ray.cluster_resources().get("GPU", 0)
        if p.concurrent > cpus:
            raise ValueError(must_be("--max-concurrent", f"at most the cluster's {cpus:g} CPUs", p.concurrent))
        cost = estimate(p, data)
        _log.info("%s", cost)
        sweep_dir = p.train.run_root / _sweep_name(p, data.sha256)
        experiment_id = ensure_experiment(p.train.experiment)
        parent = _parent_start(client, sweep_dir, experiment_id, f"sweep · {p.config.kind} · {data.body.robot}")
        with mlflow.start_run(**parent) as run:                     # an exception inside ends it FAILED
            sweep_dir.mkdir(parents=True, exist_ok=True)
            (sweep_dir / PARENT_MARKER).write_text(run.info.run_id)
            _log_parent_params(p, cost, gpus)
            gpus = gpus if p.network else 0                         # only the network kinds train on a GPU
            trials = dataclasses.replace(p.train, tracking_uri=uri, run_root=sweep_dir / "trials")
            context = TrialContext(trials, uri, experiment_id,
                                   run.info.run_id, sweep_dir.name, p.network)
            started = time.perf_counter()
            results = _fit(_tuner(p, context, sweep_dir, gpus))
            rows = sweep_report.trial_rows(client, results, p.space)
            mlflow.log_metric("sweep_seconds", time.perf_counter() - started)
            sweep_report.log_table(rows)                            # before registering: a refusal keeps it
            registered = (sweep_report.register_best(client, rows, p.config.kind, p.train.modality)
                          if p.config.register else None)
    return sweep_report.SweepResult(run.info.run_id, tuple(rows), registered, sweep_dir, cost)


def _fit(tuner):
    """tuner.fit(), Tune's tables on stderr (stdout is for our output). Ctrl-C is not Tune's (which would stop every
    trial and return as if done): it ends the parent KILLED; the same command restores the experiment, which Tune
    saves as it goes, and each unfinished trial continues its child run from its checkpoint."""
    with _env(TUNE_DISABLE_SIGINT_HANDLER="1"), contextlib.redirect_stdout(sys.stderr):
        try:
            return tuner.fit()
        except KeyboardInterrupt:
            mlflow.end_run("KILLED")
            raise


@contextlib.contextmanager
def _env(**values: str):
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _tuner(p: Plan, context: TrialContext, sweep_dir: Path, gpus: float):
    """A new Tuner, or the one restored from `sweep_dir` (a re-run after a kill continues it)."""
    from ray import tune
    from ray.tune.search.basic_variant import BasicVariantGenerator

    trainable = tune.with_resources(tune.with_parameters(run_trial, context=context),
                                    {"cpu": 1, "gpu": 1 if gpus else 0})
    if tune.Tuner.can_restore(str(sweep_dir)):
        _log.info("continuing the sweep in %s", sweep_dir)
        return tune.Tuner.restore(str(sweep_dir), trainable, resume_unfinished=True, resume_errored=True)
    return tune.Tuner(trainable, param_space=p.space.param_space(),
                      tune_config=tune.TuneConfig(scheduler=scheduler(p), num_samples=p.space.samples,
                                                  search_alg=BasicVariantGenerator(max_concurrent=p.concurrent,
                                                                                   random_state=p.config.seed)),
                      run_config=tune.RunConfig(name=sweep_dir.name, storage_path=str(sweep_dir.parent),
                                                verbose=1 if p.config.progress and log.progress_bars() else 0))


def scheduler(p: Plan):
    """ASHA on the per-epoch validation loss for a network; FIFO (every trial to its end) for a GP."""
    from ray.tune.schedulers import ASHAScheduler, FIFOScheduler

    if not p.network:
        _log.info("%s reports once, at the end of its fit: no early stopping", p.config.kind)
        return FIFOScheduler()
    # max_t one past the last epoch: ASHA stops a trial at max_t, which would cut a full trial before its score
    return ASHAScheduler(time_attr=EPOCH, metric="val_loss", mode="min", max_t=(p.max_epochs or 1) + 1,
                         grace_period=p.config.grace_period, reduction_factor=3)


def _parent_start(client, sweep_dir: Path, experiment_id: str, name: str) -> dict:
    marker = sweep_dir / PARENT_MARKER
    if marker.is_file():
        try:
            run = client.get_run(marker.read_text().strip())
            if run.info.lifecycle_stage == "active":
                return dict(run_id=run.info.run_id)
        except mlflow.exceptions.MlflowException:
            pass                                                    # another store, or deleted: a new parent
    return dict(experiment_id=experiment_id, run_name=name, tags={SWEEP_TAG: sweep_dir.name})


def _log_parent_params(p: Plan, cost, gpus: float) -> None:
    params = {"kind": p.config.kind, "modality": p.train.modality, "data": str(p.train.data),
              "trials": p.space.trials, "max_concurrent": p.concurrent, "gpus_per_trial": 1 if gpus else 0,
              "scheduler": "ASHA (val_loss per epoch)" if p.network else "FIFO (a GP reports once)",
              "estimated_cpu_s": round(cost.cpu_seconds, 1),
              **{f"space.{k}": v for k, v in p.space.describe().items()}}
    try:
        mlflow.log_params({k: str(v) for k, v in params.items()})
    except mlflow.exceptions.MlflowException:
        pass                                                        # a continued parent has them (estimate differs)


def check_memory(p: Plan, data, available: float | None = None) -> None:
    """`train`'s guards on every trial of the sweep before Ray starts (a GP on images; a fit's memory, with each
    random dimension at its high end, the largest it may draw): the house error names the trial to drop."""
    guards.check_config(p.config.kind, p.train.modalities)
    shapes = {m: data.output_shape(m) for m in p.train.modalities}
    available = guards.available_memory() if available is None else available
    for point in p.space.points():
        model_config = dataclasses.replace(p.train.model, **point)
        model = untrained_model(dataclasses.replace(p.train, model=model_config), data.body, shapes)
        try:
            for shape in shapes.values():
                guards.check_memory(p.config.kind, model, len(data.train), shape, available)
        except ValueError as error:
            trial = " ".join(f"{k}={_word(v)}" for k, v in point.items())
            raise ValueError(f"{error} (sweep trial {trial}: drop its value from --grid / --space)") from None


def _word(value) -> str:
    return "x".join(map(str, value)) if isinstance(value, tuple) else str(value)


def _sweep_name(p: Plan, dataset_sha256: str) -> str:
    """The sweep folder's name: kind, modality and the hash of everything that decides its trials."""
    identity = {**p.train.identity(dataset_sha256), "space": p.space.describe(), "samples": p.space.samples,
                "grace_period": p.config.grace_period}
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode()).hexdigest()[:12]
    return f"{p.config.kind}-{p.train.modality}-{digest}"


def _absolute(uri: str) -> str:
    path = sqlite_path(uri)
    return f"sqlite:///{path.resolve()}" if path is not None and not path.is_absolute() else uri


def _sweepable() -> list[str]:
    """The trainable kinds whose class is `sweepable` (models/capabilities.py; imports their modules)."""
    return [k.name for k in kinds.trainable() if kinds.model_class(k.name).sweepable]
