"""Estimation levels 1–3, "where is my body?": batched perception from perturbed beliefs, against the simulator.

For every run (seeded, held-out targets: targets.py) and level, all trials are inferred in one batch by
`aif.Perception` over the given models; level 3 is also run with multi-start (aif/multistart.py), and with an image
encoder every level also starts from its guess ("+enc" rows: see evaluate_runs). A run infers from each start once
(the levels' own and the guess, which the "+enc" rows share); runs are independent, several go into one batch where
that pays (`run_batch`, run_batch.py) and batches may go to worker processes (`workers`, pool.py). Metrics per
level and run: joint error (deg, per joint and mean), end-effector error (mm, simulator FK at the belief),
image MSE (with an image model), success rate (mean |joint error| < success_deg), steps, convergence,
divergence and wall time. Every run also infers its targets from their true poses: the "floor" row (floor.py),
per joint, and each level row's gap to it. Tables, plots (report.py) and one MLflow run with them as artifacts.
Robustness: `noise_sweep` and `broken_sweep` repeat one level under observation noise or a dead sensor.

Models come as objects (`run_levels(config, models=[...])`) or as specs: "analytic:<robot>:<modality>",
"models:/<name>@<alias>" (the registry, loaded lazily) or a local directory written by `model.save`.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.multistart import infer_multistart, lowest_free_energy
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.base.modalities import is_image
from bodyschema.datagen.samplers import uniform
from bodyschema.errors import must_be
from bodyschema.evaluation.core.config import TrialsConfig
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.specs import load_robot, models_field, on_device, resolve_encoder, resolve_models
from bodyschema.evaluation.levels import report as level_report
from bodyschema.evaluation.levels.floor import FLOOR_LABEL, UNOBSERVABLE_DEG, add_gaps, evaluate_floor_runs
from bodyschema.evaluation.levels.plain import PLAIN_LABEL, PLAIN_STEPS, PlainPixelAIF
from bodyschema.evaluation.levels.pool import map_runs
from bodyschema.evaluation.levels.recorded import RecordedTargets, plain_verdict
from bodyschema.evaluation.levels.run_batch import RunBatch, chunks, reads_images, runs_per_batch
from bodyschema.evaluation.levels.scoring import observations, score_runs
from bodyschema.evaluation.levels.targets import initial_beliefs, make_targets

DEFAULT_MODELS = ("analytic:planar2:ee_xyz",)
# The flow's Δt (s, k = 1) for a static reading: a direction of F's curvature λ (nats/rad²) moves by (1 − e^{−λΔt}) of
# its Newton step. Every sensed direction of the shipped modalities at their sensor precisions has λ ≥ ~10² (Newton
# steps); one the readings leave open (a 7-joint arm's self-motion under the ee's pose, a broken sensor's) has λ ≈ 0,
# and there the step is Δt × the gradient, which only the model's own error makes: at the library's Δt = 1000 a GP
# 0.03° off walked the belief 4–6° along the self-motion (issue 33's nine-arm table). At 1 it holds where it started.
STATIC_DT = 1.0
STATIC_PERCEPTION = PerceptionConfig(record=True, flow=FlowSettings(step_control="descent", dt=STATIC_DT))  # monotone


_log = logging.getLogger(__name__)

@dataclass(frozen=True)
class PerceptionRunConfig(TrialsConfig):
    """What the levels and the robustness sweeps share: the models, trials × runs and the perception update."""

    models: models_field(", ".join(DEFAULT_MODELS)) = ()
    trials: int = 500                  # per run, as in Pixel-AIF
    runs: int = 5                      # runs with different target seeds
    noise: tuple[tuple[str, float], ...] = ()   # observation noise σ per modality (m, px, rad, intensity)
    perception: PerceptionConfig = STATIC_PERCEPTION
    success_deg: float = 1.0           # a trial succeeds when its mean |joint error| is below this
    device: str = "cpu"                # where networks run: "cpu", "cuda" or "cuda:N" (the belief stays on the CPU)
    image_size: tuple[int, int] | None = None   # robot camera (H, W); default: the image model's, else the robot's
    plots: bool = True                 # write the PNG plots beside the tables


@dataclass(frozen=True)
class LevelsConfig(PerceptionRunConfig):
    """Estimation levels 1–3 on held-out targets: batched AIF perception from perturbed beliefs."""

    out: Path = Path("results/levels")               # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-levels"            # the MLflow experiment
    levels: tuple[int, ...] = (1, 2, 3)  # 1: one joint off 5–10°, 2: all joints off, 3: another target's pose
    multistart: int = 8                # starts per trial for the level-3 remedy (0: off)
    screen_steps: int = 5              # multi-start: updates before pruning (a descent trial converges in ~15)
    keep: int = 2                      # multi-start: starts per trial refined to convergence
    encoder: str | None = None         # an image encoder spec (kind "encoder"): extra "+enc" rows start from its guess
    targets: Path | None = None        # a store (e.g. imported): score its recorded frames instead of rendering
    plain_steps: int = PLAIN_STEPS     # --targets with an image model: Euler steps of the plain Pixel-AIF row (0: off)
    workers: int = 1                   # processes the runs go to, torch threads split among them (2–3 on 2 cores)
    run_batch: int = 0                 # runs inferred in one batch; 0: all of a worker's, 1 for image models on CPU
    # the "floor" row: perception started at the true pose, per joint (floor.py); one inference per run from the
    # minimum's basin, cheap for every model
    floor: bool = True
    unobservable_deg: float = UNOBSERVABLE_DEG   # a joint whose floor is above this: "not observable" in summary.md

    def __post_init__(self):
        super().__post_init__()
        if not self.unobservable_deg > 0:
            raise ValueError(must_be("unobservable_deg", "a positive number of degrees", self.unobservable_deg))
        if not self.levels or any(level not in (1, 2, 3) for level in self.levels):
            raise ValueError(must_be("levels", "a non-empty subset of (1, 2, 3)", self.levels))
        if self.multistart < 0 or self.multistart == 1:
            raise ValueError(must_be("multistart", "0 (off) or at least 2 starts", self.multistart))


@dataclass
class LevelsSummary:
    rows: list[dict]                            # one per (level, run)
    table: list[dict]                           # one per level: mean (and std) over runs
    per_trial: dict[str, np.ndarray] = field(default_factory=dict)   # level → (runs·trials,) mean error, deg
    paths: dict[str, Path] = field(default_factory=dict)
    run_id: str | None = None
    targets: dict | None = None                 # recorded targets: store path, digest, frames (None: simulator)
    floor: dict | None = None                   # the floor row: mean (and std) over runs (None: --no-floor)
    floor_rows: list[dict] = field(default_factory=list)   # the floor row of each run


# ---- one level ----------------------------------------------------------------------------------------
def evaluate_level(perception: Perception, robot, targets, level: int, rng: np.random.Generator,
                   success_deg: float = 1.0, multistart: int = 0, screen_steps: int = 20, keep: int = 2,
                   encoder=None, shared: dict | None = None):
    """Infer every target of one run from its level-`level` belief; returns (metrics row, per-trial arrays, result).
    evaluate_runs with a batch of this one run."""
    (row, trial, result), = evaluate_runs(perception, robot, RunBatch.of((targets,)), level, (rng,),
                                         success_deg, multistart, screen_steps, keep, encoder, shared)
    return row, trial, result


def evaluate_runs(perception: Perception, robot, batch: RunBatch, level: int, rngs: Sequence[np.random.Generator],
                  success_deg: float = 1.0, multistart: int = 0, screen_steps: int = 20, keep: int = 2,
                  encoder=None, shared: dict | None = None) -> list[tuple[dict, dict, object]]:
    """Infer every target of a batch of runs from its level-`level` belief, each run's drawn from its own rng, in
    one batch; returns per run (metrics row, per-trial arrays, result). The row's evaluations per trial and wall
    time are the batch's, shared by trials.

    encoder: an image encoder; its estimate from the target images is a start. Level 3 (the belief knows nothing
    of the pose): the start, the level's own one becoming the second multi-start seed. Levels 1–2 (the belief is
    near the pose): a second start beside the level's own; both run to convergence and the lower F wins.
    shared: one dict for the calls of one batch (same targets, each level's rngs drawn afresh from the same seeds):
    the encoder's guess and the inference from each start are computed once and reused by every row that starts
    there ("1" and "1+enc" share the level's start, every "+enc" row the guess's). A row's evaluations and wall time
    are those of the inferences its result needed, reused or not."""
    shared = {} if shared is None else shared
    targets = batch.targets
    obs = observations(perception, targets)
    parts = [batch.part(i) for i in range(len(batch.sizes))]
    mu0s = [initial_beliefs(level, p.q, robot.sampling_ranges, rng) for p, rng in zip(parts, rngs)]
    mu0 = np.concatenate(mu0s)                                                    # (N, Dq) rad
    label = str(level) + ("+enc" if encoder is not None else "") + ("+ms" if multistart else "")
    guess = None if encoder is None else _encoder_start(shared, encoder, robot, targets)
    if multistart:
        start = time.perf_counter()
        seeds = [mu0] if guess is None else [guess, mu0]
        extra = np.concatenate([uniform(rng, robot.sampling_ranges, len(m) * max(multistart - len(seeds), 0))
                                .reshape(len(m), -1, mu0.shape[1]) for m, rng in zip(mu0s, rngs)])
        starts = np.concatenate([s[:, None] for s in seeds] + [extra], axis=1)[:, :multistart]   # (N, S, Dq) rad
        ms = infer_multistart(perception, obs, torch.from_numpy(starts), screen_steps, keep)
        result, evaluations, wall = ms.result, ms.evaluations, time.perf_counter() - start
    else:
        runs = [] if guess is not None and level == 3 else [_inferred(shared, level, perception, obs, mu0)]
        if guess is not None:
            runs.append(_inferred(shared, "encoder", perception, obs, guess))
        result = runs[0][0] if len(runs) == 1 else lowest_free_energy([r for r, _ in runs])[0]
        evaluations, wall = result.evaluations, sum(w for _, w in runs)
    return score_runs(perception.models, robot, batch, label, result, evaluations, wall, success_deg)


def _encoder_start(shared: dict, encoder, robot, targets) -> np.ndarray:
    """The encoder's guess from the target images, clipped to the sampling box; once per batch. # (N, Dq) rad"""
    if "guess" not in shared:
        start = time.perf_counter()
        low, high = robot.sampling_ranges.T
        shared["guess"] = np.clip(encoder.encode(targets.observations[encoder.modality]).double().numpy(), low, high)
        shared["guess_s"] = time.perf_counter() - start
    return shared["guess"]


def _inferred(shared: dict, key, perception: Perception, obs, mu0: np.ndarray):
    """(result, wall s) of inferring from mu0, the start named `key` in this batch; once per batch and key."""
    if key not in shared:
        start = time.perf_counter()
        result = perception.infer(obs, torch.from_numpy(mu0))
        shared[key] = result, time.perf_counter() - start + (shared.get("guess_s", 0.0) if key == "encoder" else 0)
    return shared[key]


# ---- the benchmark ------------------------------------------------------------------------------------
def run_levels(config: LevelsConfig = LevelsConfig(), models: Sequence | None = None) -> LevelsSummary:
    """Levels × runs on held-out targets; writes tables and plots to a new run folder under config.out and logs one
    MLflow run."""
    models = resolve_models(config.models, DEFAULT_MODELS, config.tracking_uri, models)
    summary, curves = measure_levels(config, models)
    folder = new_run(config)
    summary.paths = level_report.write_all(summary, curves, folder, plots=config.plots,
                                           notes=plain_verdict(summary.table), unobservable_deg=config.unobservable_deg)
    tags = {}
    if summary.targets is not None:                       # lineage: which recorded frames were scored
        summary.paths["targets_json"] = folder / "targets.json"
        summary.paths["targets_json"].write_text(json.dumps(summary.targets, indent=2, default=str))
        tags = {"bodyschema.targets.path": summary.targets["path"], "bodyschema.targets.sha256":
                summary.targets["sha256"]}
    table = ([summary.floor] if summary.floor else []) + summary.table           # floor.<metric>, L<level>.<metric>
    metrics = table_metrics(table, lambda r: FLOOR_LABEL if r["level"] == FLOOR_LABEL else f"L{r['level']}")
    summary.run_id = publish(config, folder, "levels", metrics, summary.paths, models, tags=tags)
    return summary


def measure_levels(config: LevelsConfig, models: Sequence) -> tuple[LevelsSummary, dict[str, np.ndarray]]:
    """The levels × runs of config on resolved models, nothing written: (summary, F(t) curves per level, first
    run). Runs are independent (seeded by their index): with config.workers > 1 they are spread over processes."""
    from tqdm import tqdm
    robot, recorded = _setting(config, models)
    encoder = resolve_encoder(config.encoder, robot, config.tracking_uri)
    on_device(models + ([encoder] if encoder else []), config.device)
    workers = min(config.workers, config.runs)
    batches = chunks(config.runs, workers, runs_per_batch(config.run_batch, models, encoder, config.device))
    _log.debug("levels: %d runs in %d batch(es) of %s runs over %d process(es)", config.runs, len(batches),
               "/".join(str(len(b)) for b in batches), workers)
    done = (map_runs(measure_runs, config, models, encoder, batches, workers) if workers > 1 else
            (measure_runs(config, models, encoder, runs, robot, recorded) for runs in batches))
    rows, per_trial, curves = [], {}, {}
    bar = tqdm(desc="levels runs", total=config.runs, disable=not config.progress or config.runs < 2)
    for batch in done:
        for run_rows, run_trials, run_curves in batch:
            rows += run_rows
            for label, errors in run_trials:
                per_trial.setdefault(label, []).append(errors)
            curves = curves or run_curves
        bar.update(len(batch))
    bar.close()
    floor_rows = [r for r in rows if r["level"] == FLOOR_LABEL]
    rows = [r for r in rows if r["level"] != FLOOR_LABEL]
    summary = LevelsSummary(rows, level_report.aggregate(rows), {k: np.concatenate(v) for k, v in per_trial.items()},
                            targets=None if recorded is None else recorded.lineage(),
                            floor=level_report.aggregate(floor_rows)[0] if floor_rows else None, floor_rows=floor_rows)
    return summary, curves


def _setting(config: LevelsConfig, models: Sequence):
    """(robot, recorded targets or None) of a levels run: the models' simulated robot, or a store's body."""
    recorded = None if config.targets is None else RecordedTargets(config.targets, models, config.encoder is not None)
    if recorded is not None:
        recorded.check_enough(config.trials, config.runs)
    return (load_robot(models, config.image_size) if recorded is None else recorded.body), recorded


def measure_runs(config: LevelsConfig, models: Sequence, encoder, runs: Sequence[int], robot=None, recorded=None):
    """Every level row of the given runs, inferred in one batch (run_batch.py): per run (rows, the floor's first;
    [(level label, (N,) mean error deg)]; F(t) curves if run 0). Each start is inferred once (evaluate_runs'
    `shared`); trajectories are recorded only in the batch holding run 0 (the curves plot run 0)."""
    if robot is None:
        robot, recorded = _setting(config, models)
    perception = Perception(models, replace(config.perception, record=config.perception.record and 0 in runs))
    batch = RunBatch.of([_targets(config, models, encoder, run, robot, recorded) for run in runs])
    out = [([], [], {}) for _ in runs]
    shared = {}
    jobs = [(level, ms, enc) for level in config.levels for enc in ((False, True) if encoder else (False,))
            for ms in ((0, config.multistart) if level == 3 and config.multistart else (0,))]
    for level, ms, enc in jobs:
        rngs = [eval_rng(config.seed, run, "beliefs", level) for run in runs]   # same μ0 with and without ms
        start = time.perf_counter()
        scored = evaluate_runs(perception, robot, batch, level, rngs, config.success_deg, ms, config.screen_steps,
                               config.keep, encoder if enc else None, shared)
        _log.debug("runs %s level %s%s%s: %d trials, %.2f s", list(runs), level, f" multistart {ms}" if ms else "",
                   " +encoder" if enc else "", len(batch.targets.q), time.perf_counter() - start)
        for (rows, per_trial, curves), run, (row, trial, result) in zip(out, runs, scored):
            rows.append({"run": run, **row})
            per_trial.append((row["level"], trial["mean_err_deg"]))
            if result.trajectory is not None and not ms:                   # ms: refinement only
                curves[row["level"]] = result.trajectory["F"].numpy()      # (T, N)
        if recorded is not None and not ms and not enc and config.plain_steps and \
                any(is_image(m.modality) for m in models):               # the reference row, same frames and μ0
            plain = evaluate_runs(PlainPixelAIF(models, level, config.plain_steps), robot, batch, level,
                                  [eval_rng(config.seed, run, "beliefs", level) for run in runs], config.success_deg)
            for (rows, per_trial, _), run, (row, trial, _) in zip(out, runs, plain):
                rows.append({"run": run, **row, "level": f"{level} {PLAIN_LABEL}"})
                per_trial.append((rows[-1]["level"], trial["mean_err_deg"]))
    if config.floor:                                                       # the same targets, started at the truth
        floors = evaluate_floor_runs(perception, robot, batch, config.success_deg)
        for (rows, per_trial, _), run, (floor, trial, _) in zip(out, runs, floors):
            add_gaps(rows, floor)
            rows.insert(0, {"run": run, **floor})
            per_trial.insert(0, (FLOOR_LABEL, trial["mean_err_deg"]))
    return out


def _targets(config: LevelsConfig, models: Sequence, encoder, run: int, robot, recorded):
    """Run `run`'s targets: simulated (seeded by the run) or the store's frames of that run."""
    noise_rng = eval_rng(config.seed, run, "noise")
    if recorded is not None:
        return recorded.run(run, config.trials, dict(config.noise), noise_rng)
    return make_targets(robot, config.trials, eval_rng(config.seed, run, "targets"), reads_images(models, encoder),
                        dict(config.noise), noise_rng)


def noise_sweep(config: PerceptionRunConfig, modality: str, sigmas: Sequence[float], level: int = 2,
                models: Sequence | None = None) -> list[dict]:
    """Mean joint error vs observation noise σ on one modality (precisions unchanged: a mis-specified Π); one row
    per σ. Plot with `level_report.plot_sweep(rows, "sigma", path)` (evaluation/robustness does)."""
    models = resolve_models(config.models, DEFAULT_MODELS, config.tracking_uri, models)
    out = []
    for sigma in sigmas:
        noise = tuple((m, s) for m, s in config.noise if m != modality) + ((modality, float(sigma)),)
        cfg = at_level(config, level, noise=noise, perception=replace(config.perception, record=False))
        out.append({"modality": modality, "sigma": float(sigma), **measure_levels(cfg, models)[0].table[0]})
    return out


def broken_sweep(config: PerceptionRunConfig, models: Sequence | None = None, level: int = 2) -> list[dict]:
    """One row per modality set to precision 0 (a dead sensor), plus the intact baseline; plot with
    `level_report.plot_sweep(rows, "broken", path)`."""
    models = resolve_models(config.models, DEFAULT_MODELS, config.tracking_uri, models)
    out = []
    for dead in (None, *[m.modality for m in models]):
        pcfg = replace(config.perception, record=False,
                       precisions=config.perception.precisions + (((dead, 0.0),) if dead else ()))
        out.append({"broken": dead or "none", **measure_levels(at_level(config, level, perception=pcfg), models)[0]
                    .table[0]})
    return out


def at_level(config: PerceptionRunConfig, level: int, **changes) -> LevelsConfig:
    """The levels config of one level (no multi-start, floor, plots nor MLflow) with config's shared fields."""
    shared = {f.name: getattr(config, f.name) for f in fields(PerceptionRunConfig)}
    return LevelsConfig(**{**shared, "levels": (level,), "multistart": 0, "mlflow": False, "plots": False,
                           "progress": False, "floor": False, **changes})
