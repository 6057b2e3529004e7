"""Agency, "did I do it?": was the movement I feel and see caused by my own action?

Every episode a movement happens (streams.py): commanded by the robot itself, imposed on its arm from outside
(pushed) or shown by a scene that moved while the arm held still (scene_moved). The robot's forward model turns its
own command (efference copy) into the predicted pose q̂(t), and every SensoryModel turns q̂ into the predicted
sensation g_m(q̂). The free energy of the action's predicted consequences at a frame is

    F(t) = Σ_m ½ (x_m(t) − g_m(q̂(t)))ᵀ Π_m (x_m(t) − g_m(q̂(t))),   Π_m = 1 / (1/Π_model(q̂) + σ_m²)
(Π_m = 1/σ_m² for an exact model; the Laplace free energy of the observations at the belief the action predicts,
constants dropped; σ_m the sensor noise). The agency score is −F averaged over the episode: "I did it" = score ≥
threshold. ROC and AUC (scikit-learn) of self against each source and pooled, per sensory delay (predicted for now,
or by a forward model that knows the delay), on all senses and per sense: report.py.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bodyschema.errors import must_be
from bodyschema.evaluation.agency.report import roc_rows, write_report
from bodyschema.evaluation.agency.streams import SOURCES, delayed, episode_rng, make_episodes, observe
from bodyschema.evaluation.core.config import TrialsConfig, check_names, within
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.specs import body_and_senses, models_field, resolve_models

VISUAL = ("ee_pixel", "ee_xyz", "image")


@dataclass(frozen=True)
class AgencyConfig(TrialsConfig):
    """Own movements vs the same movements imposed from outside; ROC of "did I do it?" on free energy."""

    out: Path = Path("results/agency")            # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-agency"         # the MLflow experiment
    robot: str = "nao_arm"                # the acting body; every model must be of it
    models: models_field("analytic:<robot>:ee_pixel") = ()
    trials: int = 200                  # episodes: half self, half others split evenly over `sources`
    sources: tuple[str, ...] = SOURCES    # movements not of the robot's making: pushed, scene_moved
    steps: int = 30                    # frames per episode
    period: float = 0.05               # s between frames (control period; whole physics steps)
    delays: tuple[float, ...] = (0.0, 0.1, 0.2)   # s, sensory delays compared (0: none)
    known_delay: bool = True           # also score each delay > 0 with a forward model that knows the delay
    hold_s: tuple[float, float] = (0.2, 0.8)      # s, how long each commanded target is held
    proprio_noise: float = math.radians(1.0)      # rad, σ of the joint readings (1°)
    visual_noise: tuple[tuple[str, float], ...] = (   # σ per visual modality: px, m, intensity in [0, 1]
        ("ee_pixel", 1.0), ("ee_xyz", 0.002), ("image", 0.02))
    plots: bool = True                 # write the PNG plots beside the tables

    def __post_init__(self):
        super().__post_init__()
        check_names("sources", self.sources, SOURCES)
        if self.trials < 2 * len(self.sources):
            raise ValueError(must_be("trials", f"at least {2 * len(self.sources)} (half self, ≥ 1 per source)",
                                     self.trials, "Use ≥ 200 for a stable ROC."))
        if self.steps < 2:
            raise ValueError(must_be("steps", "at least 2", self.steps))
        if not self.period > 0:
            raise ValueError(must_be("period", "a positive duration in s", self.period))
        duration = self.steps * self.period
        within("steps × period", duration, "duration")
        if not self.delays or not all(isinstance(d, (int, float)) and 0 <= d and round(d / self.period) < self.steps
                                      for d in self.delays):
            raise ValueError(must_be("delays", f"within the episode: 0 ≤ d < {duration:g} s (steps × period)",
                                     self.delays, "A delay beyond the episode leaves nothing to see."))
        if not 0 < self.hold_s[0] <= self.hold_s[1]:
            raise ValueError(must_be("hold_s", "(low, high) s with 0 < low ≤ high", self.hold_s))
        if set(dict(self.visual_noise)) - set(VISUAL):
            raise ValueError(must_be("visual_noise", f"σ per modality among {VISUAL}", self.visual_noise))

    @property
    def default_models(self) -> tuple[str, ...]:
        return (f"analytic:{self.robot}:ee_pixel",)

    def lags(self) -> list[int]:
        """Frames of sensory delay per entry of `delays`."""
        return [round(d / self.period) for d in self.delays]


def prepare(config: AgencyConfig, models: Sequence):
    """(robot, [joints model, *visual models]); the house error for models of another robot or no visual model
    (a moved scene is seen, not felt)."""
    return body_and_senses(models, config.robot, VISUAL)


def predicted_free_energy(models: Sequence, predicted: np.ndarray, observed: dict[str, np.ndarray],
                          noise: dict[str, float]) -> dict[str, np.ndarray]:
    """modality → (N, T) ½ εᵀΠε of the observations against the sensations predicted at q̂ (N, T, Dq)."""
    n, t, dq = predicted.shape
    out = {}
    with torch.no_grad():
        for m in models:
            f = np.empty((n, t))
            for k in range(t):                                                  # one frame at a time: images
                z = torch.from_numpy(predicted[:, k])                           # (N, Dq) rad
                g = m.predict(z).to(torch.float64)                              # (N, *out)
                pi = _precision(m, z, noise.get(m.modality, 0.0))                  # (N, *out)
                err = torch.from_numpy(np.asarray(observed[m.modality][:, k], dtype=np.float64)) - g
                f[:, k] = (0.5 * pi * err ** 2).reshape(n, -1).sum(dim=1).numpy()
            out[m.modality] = f
    return out


def _precision(model, z: torch.Tensor, sigma: float) -> torch.Tensor:
    """Π of the observations (N, *out): an exact (analytic) model's only error is the sensor noise, 1/σ²; a learned
    model's own error adds to it, 1/(1/Π_model(z) + σ²). Noise-free and exact: the model's fixed precision."""
    own = model.precision(z).to(torch.float64)
    if getattr(model, "exact", False) and sigma > 0:
        return torch.full_like(own, 1.0 / sigma ** 2)
    return 1.0 / (1.0 / own + sigma ** 2)


def run_agency(config: AgencyConfig = AgencyConfig(), models: Sequence | None = None) -> dict[str, Path]:
    """Episodes → predicted consequences → free energy per delay → ROC; writes summary.md, roc.csv, episodes.csv
    and plots to a new run folder and logs one MLflow run. Returns name → path of what it wrote."""
    start = time.perf_counter()
    models = resolve_models(config.models, config.default_models, config.tracking_uri, models)
    robot, sensors = prepare(config, models)
    noise = {**dict(config.visual_noise), "joints": config.proprio_noise}
    first = np.stack([episode_rng(config.seed, i, "proprio_noise").standard_normal((config.steps, robot.dq))[0]
                      for i in range(config.trials)]) * config.proprio_noise          # (N, Dq): the first reading
    episodes = make_episodes(config, robot, first)
    energies = {}
    for delay, lag in zip(config.delays, config.lags()):
        observed = observe(robot, [m.modality for m in sensors], episodes, lag, noise, config.seed)
        energies[(delay, False)] = predicted_free_energy(sensors, episodes.predicted, observed, noise)
        if lag > 0 and config.known_delay:                  # the forward model predicts what arrives `lag` late
            late = delayed(episodes.predicted, episodes.rest, lag)
            energies[(delay, True)] = predicted_free_energy(sensors, late, observed, noise)
    wall = time.perf_counter() - start
    rows, curves = roc_rows(config, episodes.kind, episodes.failed, energies)
    out = new_run(config)
    paths = write_report(out, config, robot.name, [m.modality for m in sensors], episodes, energies, rows, curves,
                         wall)
    keep = ("auc", "fpr_at_tpr95", "failed")
    metrics = table_metrics([{"name": _metric_label(r), **{k: r[k] for k in keep}} for r in rows], "name")
    publish(config, out, "agency", {**metrics, "wall_s": wall}, paths, models)
    return paths


def _metric_label(row: dict) -> str:
    """An MLflow-safe name of a ROC row: delay<ms>ms[_known]_<source>_<senses>."""
    known = "_known" if row["known_delay"] else ""
    return f"delay{row['delay_s'] * 1000:g}ms{known}_{row['source']}_{row['senses'].replace(' ', '_')}"
