"""Tracking, "where is my arm now?": babbling arms filmed at 10–60 Hz, followed frame by frame.

For every frame rate the robot babbles `trials` streams (streams.py); each sensing condition (the given models alone,
and fused with the joint encoders) is followed side by side by every method (methods.py): the encoder alone, the
joint encoders' reading alone (fused conditions), a Pixel-AIF-style per-frame gradient flow with the tracker's budget,
and `aif.Tracker` moved by its own velocity or by the motor command. Per frame: the belief's joint error (deg) and
end-effector error (mm, simulator FK), lost track (the hand more than `lost_mm` off the truth) and the frames until
it is back, the tracker's own lost-track restarts (F above its calibrated threshold), model evaluations, and wall time
per frame with the networks' share. Tables, error-vs-time curves and plot (report.py), one MLflow run.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.tracker_config import TrackerConfig
from bodyschema.errors import must_be
from bodyschema.evaluation.core.config import TrialsConfig, check_names, within
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.sensing import through_noise
from bodyschema.evaluation.core.specs import load_robot, models_field, resolve_encoder, resolve_models
from bodyschema.evaluation.tracking import report
from bodyschema.evaluation.tracking.methods import METHODS, Clock, Timed, make_followers
from bodyschema.evaluation.tracking.streams import Streams, calibration_frames, make_streams

DEFAULT_MODELS = ("analytic:nao_arm:ee_xyz",)
SENSED = ("ee_xyz", "ee_pixel", "image", "joints")
# Every rate is a whole run's work again (its own streams, every condition and method): far above a curve's points
# (default 3: 10, 30, 60 Hz), far below a run that would not end.
MAX_RATES = 16


@dataclass(frozen=True)
class TrackingConfig(TrialsConfig):
    """Babbling streams at camera rates followed frame by frame: encoder, same-budget flow and the tracker."""

    out: Path = Path("results/tracking")             # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-tracking"          # the MLflow experiment
    models: models_field(", ".join(DEFAULT_MODELS)) = ()
    encoder: str | None = None         # image encoder spec (kind "encoder"): its row, and the tracker's restarts
    trials: int = 5                    # babbling streams per frame rate
    duration: float = 10.0             # s per stream
    rates: tuple[float, ...] = (10.0, 30.0, 60.0)   # Hz, frame rates (realised as whole physics steps)
    fuse_joints: tuple[bool, ...] = (False, True)   # the models alone, and fused with the joint encoders
    methods: tuple[str, ...] = METHODS  # encoder, reading, flow, tracker, tracker+command
    noise: tuple[tuple[str, float], ...] = (         # σ per modality: m, px, intensity in [0, 1], rad (1°)
        ("ee_xyz", 0.001), ("ee_pixel", 1.0), ("image", 0.02), ("joints", math.radians(1.0)))
    hold_s: tuple[float, float] = (0.2, 1.0)         # s each babbling target is held: datagen's (the demo's) pace
    precisions: tuple[tuple[str, float], ...] = ()   # fixed Π per modality instead of the noise rule, e.g. ee_xyz 1e6;
    # 0 ignores that modality (as in every benchmark: a dead sensor), so a condition must keep one with Π > 0;
    # unnamed, a GP (Π varying with the pose) is seen at the noise's 1/σ², as an exact model (aif/precisions.py)
    tracker: TrackerConfig = TrackerConfig()         # budget, motion order, lost-track threshold and restarts
    calibration_frames: int = 200      # poses from the model box whose F at the truth sets the lost-track threshold
    lost_mm: float = 20.0              # a frame is off track when the belief's hand is this far from the truth
    recovery_frames: int = 3           # a lost track counts as recovered when back within this many frames
    batched: bool = True               # all streams in one batch; False: one at a time (one camera's latency)
    plots: bool = True                 # write the PNG plot beside the tables

    def __post_init__(self):
        super().__post_init__()
        if not self.rates or not all(r > 0 for r in self.rates):
            raise ValueError(must_be("rates", "a non-empty tuple of frame rates > 0 in Hz", self.rates))
        if len(self.rates) > MAX_RATES or len(set(self.rates)) != len(self.rates):
            raise ValueError(must_be("rates", f"at most {MAX_RATES} distinct frame rates", f"{len(self.rates)} rates "
                                     f"({len(set(self.rates))} distinct)", "Each rate reruns every stream, condition "
                                     "and method; for more points on the curve, run again with other --rates."))
        within("frames (duration × rate)", self.duration * max(self.rates), "steps")
        check_names("methods", self.methods, METHODS)
        if not self.fuse_joints or len(set(self.fuse_joints)) != len(self.fuse_joints):
            raise ValueError(must_be("fuse_joints", "distinct flags, e.g. (False, True)", self.fuse_joints))
        for name in ("noise", "precisions"):
            if set(dict(getattr(self, name))) - set(SENSED):
                raise ValueError(must_be(name, f"values per modality among {SENSED}", getattr(self, name)))
        if not 0 < self.hold_s[0] <= self.hold_s[1]:
            raise ValueError(must_be("hold_s", "(low, high) s with 0 < low ≤ high", self.hold_s))
        if self.calibration_frames < 2 or not self.lost_mm > 0:
            raise ValueError(must_be("calibration_frames, lost_mm", "≥ 2 and > 0",
                                     (self.calibration_frames, self.lost_mm)))


@dataclass
class Followed:
    """What one method did on the streams of one rate and condition."""

    mu: np.ndarray                     # (N, T, Dq) rad; frame 0 is the start (the truth)
    restarted: np.ndarray              # (N, T) bool: the method's own lost-track restarts
    evaluations: np.ndarray            # (F,) model evaluations per stream, per followed frame (frames 1…)
    ms: np.ndarray                     # (F,) wall ms per stream, per followed frame (F = (T − 1) · streams unbatched)
    network_ms: np.ndarray             # (F,) of which inside the models and the encoder
    cpu_ms: np.ndarray                 # (F,) CPU ms of the process per stream and frame: the frame's cost without the
    # other processes of a shared machine (at one torch thread ≈ its wall time on an idle core)


# ---- the sensing conditions ----------------------------------------------------------------------------
def conditions(config: TrackingConfig, models: Sequence) -> list[tuple[str, list]]:
    """(name, models) per sensing condition: the models alone, and with the robot's joint encoders added."""
    from bodyschema.models.analytic import AnalyticModel
    seen = "+".join(m.modality for m in models)
    out = []
    for fuse in config.fuse_joints:
        if not fuse:
            out.append((seen, list(models)))
        elif all(m.modality != "joints" for m in models):
            out.append((f"{seen}+joints", [*models, AnalyticModel(models[0].body, "joints")]))
    return out


def sensed(models: Sequence, noise: dict[str, float], clock: Clock, fixed: dict[str, float] | None = None
           ) -> tuple[list, dict[str, float]]:
    """The models as the noisy sensors see them, timed, and precision overrides: `fixed` where given; else an exact
    model's only error is the noise (Π = 1/σ²), and so is a model whose precision varies with the pose (perception's
    rule, aif/precisions.py); a learned constant precision adds σ² to its own variance (core/sensing.through_noise)."""
    given = dict(fixed or {})
    seen, precisions = through_noise(models, noise, given)
    return [Timed(m, clock) for m in seen], {**given, **precisions}


# ---- following the streams -----------------------------------------------------------------------------
def follow(follower, streams: Streams, clock: Clock, rows: Sequence[int]) -> Followed:
    """Run one follower over the streams `rows`, all in one batch, from their true first pose."""
    n, t = len(rows), streams.q.shape[1]
    q0 = streams.q[rows, 0]
    mu = np.empty((n, t, q0.shape[1]))
    mu[:, 0] = q0
    restarted = np.zeros((n, t), bool)
    evaluations, ms, network, cpu = (np.zeros(t) for _ in range(4))
    follower.start(q0)
    for k in range(1, t):
        obs = {m: torch.from_numpy(x) for m, x in streams.frame(k, rows).items()}
        command = torch.from_numpy(streams.qvel[rows, k - 1])
        clock.lap()
        start, cpu_start = time.perf_counter(), time.process_time()
        step = follower.frame(obs, command, streams.period)
        ms[k] = 1e3 * (time.perf_counter() - start) / n
        cpu[k] = 1e3 * (time.process_time() - cpu_start) / n
        network[k] = clock.lap() / n
        mu[:, k], restarted[:, k], evaluations[k] = step.mu, step.restarted, step.evaluations
    return Followed(mu, restarted, evaluations[1:], ms[1:], network[1:], cpu[1:])


def follow_all(follower, streams: Streams, clock: Clock, batched: bool) -> Followed:
    """Every stream in one batch, or one after another (then each frame's time is one camera's latency)."""
    n = streams.q.shape[0]
    if batched:
        return follow(follower, streams, clock, list(range(n)))
    parts = [follow(follower, streams, clock, [i]) for i in range(n)]
    return Followed(np.concatenate([p.mu for p in parts]), np.concatenate([p.restarted for p in parts]),
                    np.concatenate([p.evaluations for p in parts]), np.concatenate([p.ms for p in parts]),
                    np.concatenate([p.network_ms for p in parts]), np.concatenate([p.cpu_ms for p in parts]))


def measure(config: TrackingConfig, models: Sequence, robot, encoder) -> tuple[list[dict], list[dict]]:
    """Every rate × condition × method: (table rows, per-frame curve rows)."""
    from tqdm import tqdm
    noise = dict(config.noise)
    all_modalities = sorted({m.modality for m in models} | {"joints"})
    q_cal, obs_cal = calibration_frames(robot, all_modalities, config.calibration_frames, noise, config.seed)
    rows, curves = [], []
    jobs = [(r, rate, c) for r, rate in enumerate(config.rates) for c in conditions(config, models)]
    streams = {}
    for r, rate, (condition, used) in tqdm(jobs, desc="tracking", disable=not config.progress or len(jobs) < 2):
        if r not in streams:
            streams = {r: make_streams(robot, all_modalities, rate, config.trials, config.duration, config.hold_s,
                                       noise, config.seed, r)}
        s = streams[r]
        clock = Clock()
        timed, precisions = sensed(used, noise, clock, {k: v for k, v in config.precisions if k in
                                                        {m.modality for m in used}})
        kept = {m.modality for m in used}
        seen = Streams(s.q, s.qvel, {m: x for m, x in s.observations.items() if m in kept}, s.period)
        calibration = (q_cal, {m: x for m, x in obs_cal.items() if m in kept})
        followers = make_followers(config.methods, timed, config.tracker,
                                   Timed(encoder, clock) if encoder is not None else None, precisions, calibration,
                                   config.seed)
        for method, follower in followers.items():
            done = follow_all(follower, seen, clock, config.batched)
            row, curve = report.score(robot, seen, done, config.lost_mm, config.recovery_frames)
            label = {"rate_hz": round(1.0 / s.period, 2), "condition": condition, "method": method}
            rows.append({**label, **row, **_settings(follower)})
            curves += [{**label, **c} for c in curve]
    return rows, curves


def _settings(follower) -> dict:
    """The tracker's lost-track threshold and the flow's Δt, for the table."""
    tracker = getattr(follower, "tracker", None)
    if tracker is None:
        return {}
    out = {"threshold_F": float(tracker.threshold)} if tracker.threshold is not None else {}
    if tracker.perception.config.flow.integrator == "euler":
        out["euler_dt"] = float(tracker.perception.config.flow.dt)
    return out


# ---- the benchmark --------------------------------------------------------------------------------------
def run_tracking(config: TrackingConfig = TrackingConfig(), models: Sequence | None = None) -> dict[str, Path]:
    """Streams → followers → errors, lost track, time per frame; writes summary.md/csv, curves.csv and the plot to a
    new run folder under config.out and logs one MLflow run. → name → path of what it wrote."""
    start = time.perf_counter()
    models = resolve_models(config.models, DEFAULT_MODELS, config.tracking_uri, models)
    check_informed(config, models)
    robot = load_robot(models)
    encoder = resolve_encoder(config.encoder, robot, config.tracking_uri)
    rows, curves = measure(config, models, robot, encoder)
    wall = time.perf_counter() - start
    folder = new_run(config)
    paths = report.write_all(folder, rows, curves, report.notes(config, robot, models, wall), config.plots,
                             report.title(robot, models, encoder))
    publish(config, folder, "tracking", {**table_metrics(rows, _label), "wall_s": wall}, paths, models)
    return paths


def check_informed(config: TrackingConfig, models: Sequence) -> None:
    """Every sensing condition keeps a modality that informs the belief: Π = 0 (--precisions m 0) ignores m, and a
    condition that sees nothing else has nothing to follow (its flow step, 1/curvature, would be infinite)."""
    ignored = {m for m, pi in config.precisions if pi == 0}
    for name, used in conditions(config, models):
        if used and all(m.modality in ignored for m in used):
            raise ValueError(must_be("precisions", f"> 0 for one modality of each sensing condition ({name}: "
                                     f"{', '.join(sorted(ignored))} ignored)", config.precisions,
                                     "Π = 0 ignores a modality; fuse the joint encoders (--fuse-joints True) or give "
                                     "the condition another model."))


def _label(row: Mapping) -> str:
    return f"{row['rate_hz']:g}Hz.{row['condition']}.{row['method']}"
