"""Self-recognition, "is this me?": does the visual stream come from my own body or from another agent?

Every episode the robot babbles, feels its joints (proprioception = q(t) + noise) and sees a visual stream
(ee_pixel, ee_xyz or images) of its own body or of another source: an imitator copying its babbling with a delay,
a gain and motor noise (one condition per delay), a second arm, or an unexplained mirror view (streams.py). All
episodes run through time as one batch. At every frame two perceptions take a few updates: `aif.Perception` over
[joints model + visual models] (one body behind both), started at the frame's joint readings, and over the visual
models alone (the stream has a body of its own; the joints are then explained by their own reading), started from
the one-body belief; the Laplace free energies of both hypotheses are recorded. The default score of an episode is
the time-average of F(one body) − F(two bodies), a free-energy model comparison
(Lanillos, Pages & Cheng 2020 score the mirror test by prediction error); `score="visual"` / `"total"` average the F
of the visual / all modalities under one body. "Is this me?" = score ≤ threshold. ROC, AUC vs delay and vs viewing
time, time to a 95 % decision: report.py. An episode whose observations turn non-finite or whose perception
diverges is marked failed with the reason and leaves the batch; the benchmark goes on.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.free_energy import sensory_terms
from bodyschema.aif.perception import Perception
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.datagen.body.record import check_robot_ref
from bodyschema.errors import must_be
from bodyschema.evaluation.core.config import TrialsConfig, check_names, within
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.specs import body_and_senses, models_field, resolve_models
from bodyschema.evaluation.self_recognition.report import roc_table, summary_notes, write_report
from bodyschema.evaluation.self_recognition.sensors import sensors_of, visual_only
from bodyschema.evaluation.self_recognition.streams import IMITATOR, Episodes, frames_of, make_episodes

SOURCES = (IMITATOR, "second_arm", "mirrored")
VISUAL = ("ee_pixel", "ee_xyz", "image")
SCORES = ("contingency", "visual", "total")
STARTS = ("reading", "previous")


@dataclass(frozen=True)
class SelfRecognitionConfig(TrialsConfig):
    """Babbling episodes seen by the robot itself or by another source; ROC of "is this me?" on free energy."""

    out: Path = Path("results/self_recognition")     # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-self-recognition"  # the MLflow experiment
    robot: str = "nao_arm"                # the babbling body (a shipped name or a model file); models are of it
    models: models_field("analytic:<robot>:ee_pixel") = ()
    trials: int = 100                  # episodes per condition: self, each imitator delay, each other source
    sources: tuple[str, ...] = (IMITATOR, "second_arm")   # other sources: imitator, second_arm, mirrored
    steps: int = 20                    # frames per episode: a 1 s viewing window
    period: float = 0.05               # s between frames (control period; realised as whole physics steps)
    delays: tuple[float, ...] = (0.0, 0.05, 0.1, 0.2, 0.3, 0.5)   # s, the imitator's lags (0: it moves with me)
    imitation_gain: float = 0.97       # the imitator's amplitude about the centre of the joint box (a close copy)
    imitation_noise: float = math.radians(0.5)   # rad, σ of the imitator's white motor noise per frame
    hold_s: tuple[float, float] = (0.2, 0.8)   # s, how long the babbler holds each random target
    proprio_noise: float = math.radians(1.0)   # rad, σ of the joint readings (1°)
    visual_noise: tuple[tuple[str, float], ...] = (  # σ per visual modality: px, m, intensity in [0, 1]
        ("ee_pixel", 2.0), ("ee_xyz", 0.004), ("image", 0.02))   # 2 px: at 1 px an exact model's AUC is 1
    score: str = "contingency"         # F(one body) − F(two bodies); "visual"/"total": F of those modalities
    perception: PerceptionConfig = PerceptionConfig(max_steps=10, tol=1e-4,
                                                    flow=FlowSettings(step_control="none"))   # ≤ 10 per frame
    # "auto": "adam+lm" with an image model (≤ 10 Adam then ≤ 10 LM steps: monotone; the flow's undamped Gauss–Newton
    # jumps left 3 % of own-body episodes off the pose), else "flow" (exact on kinematics in a few steps)
    start: str = "reading"             # one body's start per frame: "reading" (joints) or "previous" (last belief)
    plots: bool = True                 # write the PNG plots beside the tables

    def __post_init__(self):
        super().__post_init__()
        if check_robot_ref(self.robot):
            raise ValueError(check_robot_ref(self.robot))
        check_names("sources", self.sources, SOURCES)
        if self.trials < 2:
            raise ValueError(must_be("trials", "at least 2 episodes per condition", self.trials,
                                     "Use ≥ 100 for a stable ROC."))
        if not self.period > 0:
            raise ValueError(must_be("period", "a positive duration in s", self.period))
        within("steps × period", self.steps * self.period, "duration")
        self._check_imitator()
        if not 0 < self.hold_s[0] <= self.hold_s[1]:
            raise ValueError(must_be("hold_s", "(low, high) s with 0 < low ≤ high", self.hold_s))
        if set(dict(self.visual_noise)) - set(VISUAL):
            raise ValueError(must_be("visual_noise", f"σ per modality among {VISUAL}", self.visual_noise))
        if self.score not in SCORES:
            raise ValueError(must_be("score", f"one of {SCORES}", self.score))
        if self.start not in STARTS:
            raise ValueError(must_be("start", f"one of {STARTS}", self.start))

    def _check_imitator(self):
        """Delays inside the episode (the imitator copies what the robot did in view), distinct in whole frames."""
        if IMITATOR not in self.sources:
            return
        episode = self.steps * self.period
        if not self.delays or not all(d < episode for d in self.delays):
            raise ValueError(must_be("delays", f"s in [0, {episode:g}) (the episode: steps × period)", self.delays,
                                     "Shorten the delays or lengthen the episode (--steps)."))
        if len(set(frames_of(self.delays, self.period))) != len(self.delays):
            raise ValueError(must_be("delays", f"distinct in whole frames of {self.period:g} s", self.delays))
        if not self.imitation_gain > 0:
            raise ValueError(must_be("imitation_gain", "a gain > 0", self.imitation_gain))

    @property
    def default_models(self) -> tuple[str, ...]:
        return (f"analytic:{self.robot}:ee_pixel",)


@dataclass
class Scores:
    visual: np.ndarray                 # (N, T) F of the visual modalities per frame; NaN from a failure on
    total: np.ndarray                  # (N, T) F of all modalities per frame
    apart: np.ndarray                  # (N, T) F of two bodies: vision at its own belief, joints at their reading
    failed: np.ndarray                 # (N,) bool
    reason: list[str]                  # (N,) why an episode failed ("" otherwise)

    def per_frame(self, which: str = "contingency") -> np.ndarray:
        """(N, T) per frame: "contingency" = F(one body behind joints and vision) − F(a body apart), the free
        energy bound on −log p(x | one body) + log p(x | a body apart): Bayesian model comparison by free energy
        (Friston et al. 2007, the Laplace F as log evidence), which cancels what both hypotheses share (a decoder's
        pose-dependent error floor)."""
        return {"contingency": self.total - self.apart, "visual": self.visual, "total": self.total}[which]

    def score(self, which: str = "contingency") -> np.ndarray:
        """(N,) time-averaged per-frame score per episode; NaN for failed episodes."""
        return self.per_frame(which).mean(axis=1)


# ---- setup --------------------------------------------------------------------------------------------
def prepare(config: SelfRecognitionConfig, models: Sequence):
    """(robot, Perception over [joints model, *visual models], visual modalities); the house error on models of
    another robot or of a modality that has no visual stream."""
    robot, used = body_and_senses(models, config.robot, VISUAL)    # checks joints; camera of the image model
    sensors, precisions = sensors_of(config, used)
    perception = Perception(sensors, config.perception, precisions)
    return robot, perception, [m.modality for m in used[1:]]


# ---- perception through time ---------------------------------------------------------------------------
def score_episodes(perception: Perception, episodes: Episodes, visual: Sequence[str],
                   progress: bool = True, start: str = "reading") -> Scores:
    """Run perception frame by frame over all episodes at once with one body behind joints and vision, then release
    the belief to vision alone from there (the two-body hypothesis, refitted locally each frame: a vision-only belief
    tracked on its own loses an image stream's pose within a few frames); per frame, the free energies of both
    hypotheses. Episodes with a non-finite observation or a diverged belief fail.

    start: where the one-body belief starts each frame. "reading": at the frame's joint readings (the pose one body
    predicts; the previous belief's higher orders kept), inside the visual F's basin of the felt pose however far the
    arm moved since the last frame. "previous": at the last frame's belief, kept for comparison — a babbling arm moves
    up to ~25–30° between frames, the start then lies outside the felt pose's basin of an image decoder's F and the
    belief settles in another minimum that the joints do not pull it out of, even with 50 LM steps (nao_arm, 56×80
    decoder: median error 22°, its own image F 20–40× its floor from the second frame on, pooled AUC 0.53)."""
    from tqdm import tqdm
    n, t = episodes.proprio.shape[:2]
    streams = {"joints": episodes.proprio, **{m: episodes.visual[m] for m in visual}}
    scores = Scores(*(np.full((n, t), np.nan) for _ in range(3)), np.zeros(n, bool), [""] * n)
    alone = visual_only(perception)
    belief = torch.zeros(n, perception.config.order + 1, perception.latent_dim, dtype=torch.float64)
    belief[:, 0] = torch.from_numpy(np.nan_to_num(episodes.proprio[:, 0]))        # start at the joint readings
    for frame in tqdm(range(t), desc="self-recognition", disable=not progress):
        _fail_non_finite(scores, streams, frame)
        rows = np.flatnonzero(~scores.failed)
        if rows.size == 0:
            break
        obs = {m: torch.from_numpy(np.asarray(x[rows, frame], dtype=np.float64)) for m, x in streams.items()}
        begin = belief[rows].clone()                               # (b, K, Dz)
        if start == "reading":
            begin[:, 0] = obs["joints"]
        result = perception.infer(obs, begin)
        seen = {m: obs[m] for m in visual}
        apart = alone.infer(seen, result.mu_tilde)                 # released from the one-body belief
        diverged = result.diverged.numpy() | apart.diverged.numpy()
        for i in rows[diverged]:
            scores.failed[i], scores.reason[i] = True, f"perception diverged at frame {frame}"
        ok = ~diverged
        belief[rows[ok]] = result.mu_tilde[ok]
        total, per_modality = _free_energy(perception.models, perception.precisions,
                                           {m: x[ok] for m, x in obs.items()}, result.mu[ok])
        shown = {m: x[ok] for m, x in seen.items()}
        vision = np.minimum(_free_energy(alone.models, alone.precisions, shown, apart.mu[ok])[0],   # its start is
                            _free_energy(alone.models, alone.precisions, shown, result.mu[ok])[0])  # a candidate too
        joints, _ = _free_energy(perception.models[:1], perception.precisions, {"joints": obs["joints"][ok]},
                                 obs["joints"][ok])                 # its own body: the readings, ε = 0
        scores.total[rows[ok], frame] = total
        scores.visual[rows[ok], frame] = sum(per_modality[m] for m in visual)
        scores.apart[rows[ok], frame] = vision + joints
    for f in (scores.visual, scores.total, scores.apart):
        f[scores.failed] = np.nan
    return scores


def _fail_non_finite(scores: Scores, streams: dict[str, np.ndarray], frame: int) -> None:
    for name, x in streams.items():
        bad = ~np.isfinite(x[:, frame].reshape(len(x), -1)).all(axis=1) & ~scores.failed
        for i in np.flatnonzero(bad):
            scores.failed[i], scores.reason[i] = True, f"non-finite {name} observation at frame {frame}"


def _free_energy(models: Sequence, precisions: dict, obs: dict[str, torch.Tensor], mu: torch.Tensor):
    """Laplace F (B,) (½ εᵀΠε − ½ log|Π| summed over the models) and ½ εᵀΠε per modality (B,) at the beliefs mu
    (B, Dz), with a perception's precision overrides."""
    pis = {m.modality: (torch.as_tensor(precisions[m.modality], dtype=torch.float64)
                        .expand(mu.shape[0], *m.output_shape) if m.modality in precisions else None)
           for m in models}
    with torch.no_grad():
        terms = sensory_terms(models, obs, pis, mu, need_hessian=False, need_grad=False)
    return terms.free_energy.numpy(), {m: e.numpy() for m, e in terms.weighted.items()}


# ---- the benchmark --------------------------------------------------------------------------------------
def run_self_recognition(config: SelfRecognitionConfig = SelfRecognitionConfig(),
                         models: Sequence | None = None) -> dict[str, Path]:
    """Episodes → perception → scores → ROC; writes summary.md/csv, episodes.csv and plots to a new run folder under
    config.out and logs one MLflow run (config.mlflow). Returns name → path of what it wrote."""
    start = time.perf_counter()
    models = resolve_models(config.models, config.default_models, config.tracking_uri, models)
    robot, perception, visual = prepare(config, models)
    episodes = make_episodes(config, robot, visual)
    scores = score_episodes(perception, episodes, visual, config.progress, config.start)
    wall = time.perf_counter() - start
    per_frame = scores.per_frame(config.score)                           # (N, T)
    rows, curves, over_time = roc_table(episodes.kind, episodes.condition, episodes.delay, per_frame,
                                        scores.failed, episodes.period)
    per_episode = [{"episode": i, "kind": k, "condition": c, "failed": bool(f), "reason": r,
                    **{f"score_{name}": float(scores.score(name)[i]) for name in SCORES}}
                   for i, (k, c, f, r) in enumerate(zip(episodes.kind, episodes.condition, scores.failed,
                                                        scores.reason))]
    lines = summary_notes(config, robot.name, visual, episodes.period, rows, scores, wall)
    out = new_run(config)
    paths = write_report(out, per_episode, rows, curves, over_time, lines, episodes.condition,
                         scores.failed, per_frame, episodes.period, config.plots)
    keep = ("comparison", "auc", "threshold", "tpr", "fpr", "t95_s", "t_auc95_s", "failed")
    metrics = table_metrics([{k: r[k] for k in keep} for r in rows], "comparison")
    publish(config, out, "self_recognition", {**metrics, "wall_s": wall}, paths, models)
    return paths
