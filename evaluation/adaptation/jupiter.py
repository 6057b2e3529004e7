"""Adaptation (b), "Jupiter": gravity jumps from 9.81 to 24.79 m/s² mid-task on a torque-driven arm (the panda).

As in the AIC paper's experiment (Pezzato, Ferrari & Hernández Corbato 2020, §VI), the same joint goals are held
by three controllers from the same start poses: the PD baseline with Earth-gravity compensation
(control/pd.py, the "built-in" controller), the unimodal AIC (joint sensors) and the multimodal AIC (joints +
an extra SensoryModel, by default the analytic ee_xyz). Recorded over time: the joint tracking error (deg, mean
over joints) and the end-effector error (mm). Summary per controller: steady error before and after the switch,
peak error after it, settle time, failed episodes. An episode whose controller or simulation fails (non-finite
input, diverged belief, unstable physics) is marked failed with its reason and the benchmark goes on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.aic import AICController
from bodyschema.aif.aic_config import AICConfig
from bodyschema.base.modalities import is_image
from bodyschema.control.pd import PDConfig, PDController
from bodyschema.control.sim import ArmBatch, control_substeps
from bodyschema.datagen.body.robot import GRAVITY, Robot
from bodyschema.errors import must_be
from bodyschema.evaluation.adaptation.jupiter_report import ControllerRun, summarize, write_report
from bodyschema.evaluation.core.config import TrialsConfig
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.sensing import sense_all
from bodyschema.evaluation.core.specs import check_models_match, models_field, resolve_models
from bodyschema.threads import pinned

TIMESTEP = 0.002                   # s, the default robot's (panda MJCF's) MuJoCo step
READY = (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)   # rad, Franka's "ready" pose: goals and starts around it
MIN_EE_HEIGHT = 0.15               # m; the fingertip collides with the floor, keep goals and starts above it
SENSED = ("ee_xyz", "ee_pixel", "image")   # extra modalities the loop simulates


@dataclass(frozen=True)
class JupiterConfig(TrialsConfig):
    """PD vs unimodal vs multimodal AIC on `robot` while gravity jumps to Jupiter's mid-task."""

    out: Path = Path("results/adaptation/jupiter")   # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-adaptation"        # the MLflow experiment
    robot: str = "panda"               # the arm whose gravity changes: torque-controlled, its record has a [pd] table
    trials: int = 10                   # random reachable joint goals (and start poses) around the ready pose
    duration: float = 12.0             # s of simulated time per episode
    switch_time: float = 6.0           # s; gravity 9.81 → jupiter_gravity here
    jupiter_gravity: float = 24.79     # m/s²
    control_rate: float = 500.0        # Hz; 1 / (rate · 0.002 s) must be a whole number of MuJoCo steps
    models: models_field("analytic:<robot>:ee_xyz (the multimodal AIC's extra sensor)") = ()
    aic: AICConfig = AICConfig()       # the active inference controller's gains and precisions
    pd: PDConfig = PDConfig()          # the baseline's gains and the gravity its compensation was identified under
    spread: float = 0.4                # rad; goals and starts uniform in READY ± spread (inside the joint ranges)
    steady_window: float = 1.0         # s; steady error = mean error over the last window before the switch / the end
    settle_deg: float = 0.1            # deg; settled once the joint error stays below this until the end

    def __post_init__(self):
        super().__post_init__()
        if not 0 < self.switch_time < self.duration:
            raise ValueError(must_be("switch_time", f"inside (0, duration = {self.duration}) s", self.switch_time))
        if not (0 < self.steady_window <= min(self.switch_time, self.duration - self.switch_time) + 1e-9):
            raise ValueError(must_be("steady_window", "> 0 and no longer than the phases before and after the switch",
                                     self.steady_window))
        if not (self.spread > 0 and self.settle_deg > 0):
            raise ValueError(must_be("spread and settle_deg", "> 0", (self.spread, self.settle_deg)))
        control_substeps(self.control_rate, TIMESTEP, "control_rate")


# ---- episodes ---------------------------------------------------------------------------------------------
def sample_poses(robot: Robot, n: int, spread: float, rng: np.random.Generator) -> np.ndarray:
    """n poses uniform in READY ± spread, clipped to the sampling ranges, with the fingertip above the floor."""
    low, high = robot.sampling_ranges.T
    out = []
    while len(out) < n:
        q = np.clip(np.asarray(READY) + rng.uniform(-spread, spread, (n, robot.dq)), low, high)   # (n, Dq) rad
        out.extend(q[robot.fk(q)[:, 2] > MIN_EE_HEIGHT])
    return np.array(out[:n])


def load_torque_robot(name: str, models: Sequence) -> Robot:
    """Robot `name` on motors, with the camera the image / pixel models (if any) were made for; checks the models."""
    for m in models:
        if m.modality not in SENSED:
            raise ValueError(must_be(f"{m.modality} model", f"of a simulated extra modality {SENSED}", m.modality,
                                     "The joints sensor is built into the AIC; drop the joints model."))
    image = next((m for m in models if is_image(m.modality)), None)
    pixel = next((m for m in models if getattr(m, "image_size", None)), None)
    size = tuple(image.output_shape[:2]) if image else (tuple(pixel.image_size) if pixel else None)
    rgb = image is not None and len(image.output_shape) == 3
    robot = Robot.load(name, image_size=size, rgb=rgb, actuators="torque")
    check_models_match(models, robot)
    return robot


def simulate(robot: Robot, controller, models: Sequence, starts: np.ndarray, goals: np.ndarray,
             config: JupiterConfig, desc: str = "") -> dict[str, np.ndarray | list]:
    """Run B episodes side by side through one controller (reset/act interface); gravity switches at switch_time.
    → t (T,) s, q (T, B, Dq) rad at every control tick, failed (B,), reasons."""
    with pinned(1):                        # per-tick tensors are tiny: intra-op threads only add sync (6× slower)
        return _simulate(robot, controller, [m.modality for m in models], starts, goals, config, desc)


def _simulate(robot: Robot, controller, sensed: Sequence[str], starts: np.ndarray, goals: np.ndarray,
              config: JupiterConfig, desc: str) -> dict[str, np.ndarray | list]:
    from tqdm import tqdm
    substeps = control_substeps(config.control_rate, robot.model.opt.timestep, "control_rate")
    period = substeps * robot.model.opt.timestep
    ticks = int(round(config.duration / period))
    t = np.arange(ticks) * period
    qs = np.empty((ticks, *starts.shape))
    with ArmBatch(robot, starts) as arms:                                 # Earth's gravity back on exit
        arms.set_gravity(GRAVITY)
        controller.reset(starts, np.zeros_like(starts), {"joints": torch.from_numpy(goals)})
        for i in tqdm(range(ticks), desc=desc, disable=not config.progress, leave=False):
            if t[i] >= config.switch_time:
                arms.set_gravity(config.jupiter_gravity)
            q, qd = arms.q, arms.qd
            qs[i] = q
            torque = controller.act(q, qd, sense_all(robot, sensed, q), period)   # the extra models' streams
            arms.step(torque, substeps, skip=controller.failed)
    reasons = [c or a for c, a in zip(controller.reasons, arms.reasons)]
    return {"t": t, "q": qs, "failed": np.array([r is not None for r in reasons]), "reasons": reasons}


# ---- metrics ---------------------------------------------------------------------------------------------
def errors(robot: Robot, q: np.ndarray, goals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint error (T, B) deg (mean |q − q_d| over joints) and ee error (T, B) mm at every tick."""
    joint = np.rad2deg(np.abs(q - goals[None])).mean(-1)
    flat = q.reshape(-1, q.shape[-1])
    ee = robot.fk_and_jacobian(flat, check=False)[0].reshape(*q.shape[:2], 3)   # vectorized FK, (T, B, 3) m
    ee_goal = robot.fk(goals)                                              # (B, 3) m
    return joint, 1e3 * np.linalg.norm(ee - ee_goal[None], axis=-1)


def episode_metrics(t: np.ndarray, joint: np.ndarray, ee: np.ndarray, config: JupiterConfig) -> list[dict]:
    """Per episode: steady errors before / after the switch, peak after it, settle time (NaN: never settled)."""
    before = (t >= config.switch_time - config.steady_window) & (t < config.switch_time)
    after, end = t >= config.switch_time, t >= t[-1] + (t[1] - t[0]) - config.steady_window
    rows = []
    for b in range(joint.shape[1]):
        outside = np.flatnonzero(after & (joint[:, b] >= config.settle_deg))
        if not outside.size:
            settle = 0.0
        elif outside[-1] == len(t) - 1:
            settle = float("nan")                                          # still outside at the end
        else:
            settle = float(t[outside[-1] + 1] - config.switch_time)
        rows.append({"joint_err_before_deg": float(joint[before, b].mean()),
                     "joint_err_after_deg": float(joint[end, b].mean()),
                     "joint_peak_after_deg": float(joint[after, b].max()),
                     "ee_err_before_mm": float(ee[before, b].mean()), "ee_err_after_mm": float(ee[end, b].mean()),
                     "ee_peak_after_mm": float(ee[after, b].max()), "settle_s": settle})
    return rows


# ---- the benchmark ---------------------------------------------------------------------------------------
def run_jupiter(config: JupiterConfig = JupiterConfig(), models: Sequence | None = None) -> dict[str, Path]:
    """PD, AIC-unimodal and AIC-multimodal on the same goals and starts; writes tables and plots to config.out."""
    models = resolve_models(config.models, (f"analytic:{config.robot}:ee_xyz",), config.tracking_uri, models)
    robot = load_torque_robot(config.robot, models)
    control_substeps(config.control_rate, robot.model.opt.timestep, "control_rate")
    goals = sample_poses(robot, config.trials, config.spread, eval_rng(config.seed, 0, "targets"))
    starts = sample_poses(robot, config.trials, config.spread, eval_rng(config.seed, 0, "starts"))
    limits = robot.model.actuator_ctrlrange.copy()                          # (Dq, 2) N·m
    multimodal = "AIC " + " + ".join(["joints", *(m.modality for m in models)])
    controllers = {"PD + g(q) on Earth": (PDController(config.robot, config.pd), []),
                   "AIC joints": (AICController([], config.aic, limits), [])}
    if models:
        controllers[multimodal] = (AICController(models, config.aic, limits), models)
    runs = []
    for name, (controller, extra) in controllers.items():
        sim = simulate(robot, controller, extra, starts, goals, config, desc=name)
        joint, ee = errors(robot, sim["q"], goals)
        run = ControllerRun(name, sim["t"], sim["q"], joint, ee)
        for b, row in enumerate(episode_metrics(sim["t"], joint, ee, config)):
            failed = bool(sim["failed"][b])
            run.rows.append({"controller": name, "episode": b, **{k: (np.nan if failed else v) for k, v in row.items()},
                             "failed": failed, "reason": sim["reasons"][b] or ""})
        runs.append(run)
    out = new_run(config)
    paths = write_report(runs, goals, config, out)
    publish(config, out, "jupiter", table_metrics(summarize(runs), "controller"), paths, models)
    return paths
