"""The rubber-hand illusion: does the belief about the hidden hand drift towards a seen, displaced hand?

Per episode the arm rests at q* (scene.py); proprioception stays true (q* + noise at every frame) while the camera
sees a hand displaced by d m towards the image centre (ee_xyz or ee_pixel models). A brush strokes the real hand
(felt) and the seen one, synchronously or with a lag (stroking.py); the posterior q(own) that the seen hand is
mine weights the visual precision. All episodes of every condition (displacement × visual σ × stroking mode) run
as one batch through time: at every frame `aif.Perception` over [joints model, visual models] takes a few updates
warm-started from the previous belief, with Π_joints = 1/σ_p² and Π_visual = q(own, t)/σ_v². The drift at a frame
is the belief's hand, fk(μ), moved towards the seen hand: (fk(μ) − fk(q*)) · d̂, m. Tables and plots: report.py.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.errors import must_be
from bodyschema.evaluation.core.config import TrialsConfig, check_names, within
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.sensing import sense
from bodyschema.evaluation.core.specs import body_and_senses, models_field, resolve_models
from bodyschema.evaluation.rubber_hand.report import condition_table, write_report
from bodyschema.evaluation.rubber_hand.scene import camera_frame, episode_rng, rest_poses
from bodyschema.evaluation.rubber_hand.stroking import MODES, felt_strokes, ownership, strokes

VISUAL = ("ee_xyz", "ee_pixel")


@dataclass(frozen=True)
class RubberHandConfig(TrialsConfig):
    """A seen hand displaced from the real one, stroked in or out of sync: the belief's drift towards it."""

    out: Path = Path("results/rubber_hand")          # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-rubber-hand"        # the MLflow experiment
    robot: str = "planar2"             # the resting arm; planar2's camera keeps a hand moved 30 cm in view
    models: models_field("analytic:<robot>:ee_xyz") = ()
    trials: int = 10                   # episodes per condition (displacement × visual σ × mode)
    displacements: tuple[float, ...] = (0.05, 0.10, 0.20, 0.30)   # m, seen hand − real hand (people: 15–30 cm)
    visual_sigmas: tuple[float, ...] = (0.005, 0.01, 0.02, 0.05)  # m, σ of the seen hand's position: Π_v = 1/σ²
    modes: tuple[str, ...] = MODES[:2]  # stroking: synchronous, asynchronous (also: vision_only, no brush)
    duration: float = 30.0             # s of stroking per episode
    period: float = 0.25               # s between perception frames
    proprio_noise: float = math.radians(2.0)   # rad, σ of the joint readings: Π_joints = 1/σ²
    visual_noise: bool = True          # add the σ noise to the seen hand (False: σ sets the precision only)
    stroke_rate_hz: float = 1.0        # brush strokes per s (about the pace of people's experiments)
    stroke_jitter_s: float = 0.1       # s, ± uniform jitter of each interval between strokes
    async_lag_s: float = 0.5           # s, seen strokes behind the felt ones when asynchronous (half a stroke)
    binding_sigma_s: float = 0.2       # s, σ of seen − felt stroke time for a hand that is mine (people: ≲ 0.3 s)
    spatial_sigma: float = 0.15        # m, σ of seen − felt hand position for a hand that is mine
    spatial_range: float = 0.6         # m, where a hand that is not mine may lie (uniform)
    prior_own: float = 0.05            # q(own) before any stroke: a fake hand is a priori not mine (onset ~10 s)
    final_window_s: float = 5.0        # s; the final drift is the mean drift over this last window
    perception: PerceptionConfig = PerceptionConfig(max_steps=20, tol=1e-6)   # updates per frame
    plots: bool = True                 # write the PNG plots beside the tables

    def __post_init__(self):
        super().__post_init__()
        for name in ("displacements", "visual_sigmas"):
            values = getattr(self, name)
            if not values or not all(v > 0 for v in values):
                raise ValueError(must_be(name, "a non-empty tuple of distances > 0 in m", values))
        check_names("modes", self.modes, MODES)
        for name in ("period", "stroke_rate_hz", "binding_sigma_s", "spatial_sigma", "spatial_range"):
            if not getattr(self, name) > 0:
                raise ValueError(must_be(name, "positive", getattr(self, name)))
        if not 0 < self.final_window_s <= self.duration:
            raise ValueError(must_be("final_window_s", f"in (0, duration = {self.duration} s]", self.final_window_s))
        if self.period > self.duration:
            raise ValueError(must_be("period", f"at most the duration ({self.duration} s)", self.period))
        within("frames (duration / period)", self.frames, "steps")
        within("strokes (duration × stroke_rate_hz)", self.duration * self.stroke_rate_hz, "strokes")
        if not 0 <= self.async_lag_s < self.duration:
            raise ValueError(must_be("async_lag_s", f"within the episode: 0 ≤ lag < {self.duration:g} s",
                                     self.async_lag_s, "A lag beyond the episode leaves no stroke to compare."))
        if not 0 <= self.stroke_jitter_s < 0.5 / self.stroke_rate_hz:
            raise ValueError(must_be("stroke_jitter_s", f"≥ 0 and below half a stroke "
                                     f"({0.5 / self.stroke_rate_hz} s)", self.stroke_jitter_s))
        if not 0 < self.prior_own < 1 or not self.proprio_noise > 0:
            raise ValueError(must_be("prior_own and proprio_noise", "0 < prior_own < 1 and σ > 0 rad",
                                     (self.prior_own, self.proprio_noise)))

    @property
    def default_models(self) -> tuple[str, ...]:
        return (f"analytic:{self.robot}:ee_xyz",)

    @property
    def frames(self) -> int:
        return max(1, round(self.duration / self.period))

    def conditions(self) -> list[tuple[float, float, str]]:
        """(displacement m, visual σ m, mode) for every condition, in table order."""
        return list(itertools.product(self.displacements, self.visual_sigmas, self.modes))


@dataclass
class Episodes:
    condition: np.ndarray              # (N,) int, index into config.conditions()
    real_xyz: np.ndarray               # (N, 3) m, the resting hand
    direction: np.ndarray              # (N, 3) unit, from the real hand towards the seen one
    proprio: np.ndarray                # (N, T, Dq) rad, joint readings
    visual: dict[str, np.ndarray]      # modality → (N, T, *out): what the camera sees of the seen hand
    visual_precision: dict[str, np.ndarray]   # modality → (N,) 1/σ² in the modality's units
    own: np.ndarray                    # (N, T) q(own) after the strokes up to each frame
    times: np.ndarray                  # (T,) s, frame times


# ---- setup --------------------------------------------------------------------------------------------
def prepare(config: RubberHandConfig, models: Sequence):
    """(robot, [joints model, *visual models], visual modalities); the house error for models of another robot or
    without a seen-hand modality."""
    robot, used = body_and_senses(models, config.robot, VISUAL, "The seen hand is a point moved in space: an image "
                                  "model would need a rendered fake hand.")
    return robot, used, [m.modality for m in used[1:]]


def make_episodes(config: RubberHandConfig, robot, visual: Sequence[str]) -> Episodes:
    """Every condition's episodes; trial i shares its pose, strokes and noise draws across conditions."""
    conditions, n, t = config.conditions(), config.trials, config.frames
    poses, dirs = rest_poses(robot, n, config.seed, max(config.displacements))      # (n, Dq), (n, 3): the house
    real = robot.fk(poses, check=False)                                             # error before any work
    times = (np.arange(t) + 1) * config.period                                      # (T,) s
    felt = [felt_strokes(episode_rng(config.seed, i, "strokes"), config.duration, config.stroke_rate_hz,
                         config.stroke_jitter_s) for i in range(n)]
    eps_p = np.stack([episode_rng(config.seed, i, "proprio_noise").standard_normal((t, robot.dq)) for i in range(n)])
    eps_v = np.stack([episode_rng(config.seed, i, "visual_noise").standard_normal((t, 3)) for i in range(n)])
    cond = np.repeat(np.arange(len(conditions)), n)                                 # (N,)
    trial = np.tile(np.arange(n), len(conditions))                                  # (N,)
    disp = np.array([conditions[c][0] for c in cond])[:, None]                      # (N, 1) m
    sigma = np.array([conditions[c][1] for c in cond])                              # (N,) m
    seen = real[trial] + disp * dirs[trial]                                         # (N, 3) m
    noise = eps_v[trial] * sigma[:, None, None] if config.visual_noise else np.zeros_like(eps_v[trial])
    seen_t = seen[:, None, :] + noise                                               # (N, T, 3) m
    out_visual, precision = {}, {}
    for m in visual:
        flat = sense(robot, m, np.zeros((seen_t.shape[0] * t, robot.dq)), xyz=seen_t.reshape(-1, 3))
        out_visual[m] = flat.reshape(len(cond), t, -1)                              # (N, T, 3 | 2)
        scale = 1.0 if m == "ee_xyz" else robot.intrinsics()[0, 0] / camera_frame(robot, seen)[:, 2]   # px/m
        precision[m] = 1.0 / (sigma * scale) ** 2                                   # (N,) m⁻² | px⁻²
    proprio = poses[trial][:, None, :] + config.proprio_noise * eps_p[trial]        # (N, T, Dq) rad
    pairs = [strokes(felt[i], conditions[c][2], config.async_lag_s) for i, c in zip(trial, cond)]
    own = ownership([f for f, _ in pairs], [s for _, s in pairs], disp[:, 0], times, config)   # (N, T)
    return Episodes(cond, real[trial], dirs[trial], proprio, out_visual, precision, own, times)


# ---- perception through time ---------------------------------------------------------------------------
def track_drift(config: RubberHandConfig, robot, models: Sequence, episodes: Episodes) -> tuple[np.ndarray, np.ndarray]:
    """(drift (N, T) m towards the seen hand per frame, failed (N,) bool): perception frame by frame, warm-started;
    an episode whose perception diverges keeps NaN from there on."""
    from tqdm import tqdm
    n, t = episodes.own.shape
    drift, failed = np.full((n, t), np.nan), np.zeros(n, bool)
    belief = torch.from_numpy(episodes.proprio[:, 0].copy())                       # (N, Dq): start at the felt hand
    pi_joints = 1.0 / config.proprio_noise ** 2
    for f in tqdm(range(t), desc="rubber hand", disable=not config.progress):
        precisions = {"joints": pi_joints, **{m: torch.from_numpy(episodes.own[:, f] * p)[:, None]
                                              for m, p in episodes.visual_precision.items()}}
        obs = {"joints": torch.from_numpy(episodes.proprio[:, f]),
               **{m: torch.from_numpy(x[:, f]) for m, x in episodes.visual.items()}}
        result = Perception(models, config.perception, precisions).infer(obs, belief)
        failed |= result.diverged.numpy()
        belief = torch.where(result.diverged[:, None], belief, result.mu)
        hand = robot.fk(belief.numpy(), check=False)                               # (N, 3) m
        drift[:, f] = ((hand - episodes.real_xyz) * episodes.direction).sum(axis=1)
        drift[failed, f] = np.nan
    return drift, failed


# ---- the benchmark --------------------------------------------------------------------------------------
def run_rubber_hand(config: RubberHandConfig = RubberHandConfig(), models: Sequence | None = None) -> dict[str, Path]:
    """Episodes → perception through time → drift per condition; writes summary.md, conditions.csv, over_time.csv,
    episodes.csv and plots to a new run folder and logs one MLflow run. Returns name → path of what it wrote."""
    start = time.perf_counter()
    models = resolve_models(config.models, config.default_models, config.tracking_uri, models)
    robot, sensors, visual = prepare(config, models)
    episodes = make_episodes(config, robot, visual)
    drift, failed = track_drift(config, robot, sensors, episodes)
    wall = time.perf_counter() - start
    rows, over_time = condition_table(config, episodes, drift, failed)
    out = new_run(config)
    paths = write_report(out, config, robot.name, visual, episodes, drift, failed, rows, over_time, wall)
    keep = ("drift_cm", "drift_fraction", "own", "failed")
    metrics = table_metrics([{"name": _metric_label(r), **{k: r[k] for k in keep}} for r in rows], "name")
    publish(config, out, "rubber_hand", {**metrics, "wall_s": wall}, paths, models)
    return paths


def _metric_label(row: dict) -> str:
    """An MLflow-safe name of a condition row: d<cm>cm_sigma<cm>cm_<mode>."""
    return f"d{row['displacement_cm']:g}cm_sigma{row['visual_sigma_cm']:g}cm_{row['mode']}"
