"""Adaptation (a): the visual end-effector marker shifted at run time, a conflict between vision and proprioception.

nao_arm holds a goal (the end-effector pixel of a held-out pose, or that pose's joints) under active inference
(aif/action.py: perception fusing joint encoders and the seen marker pixel, action driven by both). At
`shift_time` the marker moves in the hand's frame — "left"/"right" (±y), "finger" (+x, further out), "forearm"
(−x, back onto the forearm) — while every model still predicts it at the hand. With action driven by joints
and vision (linearized at the goal, x_px = J q; Π_q, Π_v the joint and pixel precisions) the steady state
puts the belief's pixel on the goal and moves the hand by e = −(I + C)⁻¹ C d with C = (Π_v/Π_q) J Jᵀ and d the
seen shift (px): the hand moves to bring the seen marker toward the goal, by the fraction `predicted_correction`
(0: vision ignored, 1: the seen marker back on the goal), more for higher visual precision. Recorded over time:
joints, belief, true hand (m, px), seen marker (px), pixel errors to the goal. Per episode: hand displacement
after the shift (mm, px), measured correction, final errors; summary per (shift, visual precision).
Simulation: position servos (ctrl += a·Δt, clipped to ctrlrange; `mj_step` over the control period's substeps),
started at rest on the goal pose (servo targets offset by the gravity torque / kp so the arm does not sag).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.action import ActionConfig, VelocityController
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.control.sim import ArmBatch, control_substeps
from bodyschema.errors import must_be
from bodyschema.evaluation.adaptation import marker_shift_report as report
from bodyschema.evaluation.core.config import TrialsConfig
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.seeds import eval_rng
from bodyschema.evaluation.core.sensing import sense, sense_all
from bodyschema.evaluation.core.specs import load_robot, models_field, resolve_models

# Unit direction of each shift in the hand (LForeArm body) frame: x along the forearm towards the marker, y the
# side (left at q = 0), times the offset size. "forearm" goes twice as far back: the hand capsule spans the last
# 34 mm before the marker (56–90 mm of 114 mm), so one offset of a few cm would still sit on the hand. Rendered
# for an image model, a marker 2×3 cm back lies inside the forearm capsule (r 18 mm): hidden, not shifted.
SHIFTS = {"none": (0.0, 0.0, 0.0), "left": (0.0, 1.0, 0.0), "right": (0.0, -1.0, 0.0),
          "finger": (1.0, 0.0, 0.0), "forearm": (-2.0, 0.0, 0.0)}
GOALS = ("ee_pixel", "joints", "image")
VISUAL = ("ee_pixel", "image")      # modalities that see the marker
TARGET_KEY = 0x5417                 # extra seed word: goal poses held out from the levels' and reaching's targets

DEFAULT_MODELS = ("analytic:nao_arm:joints", "analytic:nao_arm:ee_pixel")


@dataclass(frozen=True)
class MarkerShiftConfig(TrialsConfig):
    """nao_arm holds a goal by active inference while its visual marker is shifted in the hand frame."""

    out: Path = Path("results/adaptation/marker_shift") # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-adaptation"        # the MLflow experiment
    models: models_field(", ".join(DEFAULT_MODELS)) = ()
    trials: int = 10                   # goal poses per shift (the same poses for every shift and precision)
    shifts: tuple[str, ...] = ("left", "right", "finger", "forearm")   # hand frame ±y, +x, −x; "none": control
    offset: float = 0.03               # m, size of the shift in the hand frame (a few cm; "forearm" goes 2×)
    duration: float = 4.0              # s per episode
    shift_time: float = 1.0            # s; the hold before it shows the unshifted loop is at rest
    control_rate: float = 100.0        # Hz, whole 2 ms MuJoCo steps; at 50 Hz Π_v = 10 makes limit cycles
    visual_precisions: tuple[float, ...] = (0.1, 1.0, 10.0)   # Π of ee_pixel, px⁻²: low to high trust in vision
    goal: str = "ee_pixel"             # "ee_pixel": marker pixel at the goal pose | "joints": the pose | "image"
    # vision drives action too: driven by joints alone the conflict stays in the belief and the hand barely moves
    action: ActionConfig = ActionConfig(drive=("joints", "ee_pixel"))
    perception: PerceptionConfig = PerceptionConfig(flow=FlowSettings(step_control="none"))   # the controller's

    def __post_init__(self):
        super().__post_init__()
        bad = [s for s in self.shifts if s not in SHIFTS]
        if not self.shifts or bad:
            raise ValueError(must_be("shifts", f"a non-empty subset of {tuple(SHIFTS)}", self.shifts,
                                     f"Unknown: {bad}." if bad else ""))
        if not (0 <= self.shift_time < self.duration):
            raise ValueError(must_be("shift_time", f"in [0, duration = {self.duration}) s", self.shift_time))
        if not self.control_rate > 0:
            raise ValueError(must_be("control_rate", "a positive rate in Hz", self.control_rate))
        if not self.visual_precisions or not all(p > 0 for p in self.visual_precisions):
            raise ValueError(must_be("visual_precisions", "one or more finite precisions > 0 in px⁻²",
                                     self.visual_precisions, "Use a small value (0.01) for 'barely trusted'."))
        if self.goal not in GOALS:
            raise ValueError(must_be("goal", f"one of {GOALS}", self.goal))


def marker_offsets(shifts: Sequence[str], size: float) -> np.ndarray:
    """(S, 3) m, the marker's displacement in the hand frame for each shift name."""
    unknown = [s for s in shifts if s not in SHIFTS]
    if unknown:
        raise ValueError(must_be("shift", f"one of {tuple(SHIFTS)}", unknown[0]))
    return size * np.array([SHIFTS[s] for s in shifts], dtype=np.float64)


def vision_modality(models: Sequence) -> str:
    """The modality that sees the marker (ee_pixel, else image); the house error unless joints and vision are both
    modelled, since the experiment is their conflict."""
    modalities = [m.modality for m in models]
    vision = [m for m in VISUAL if m in modalities]
    if "joints" not in modalities or not vision:
        raise ValueError(must_be("models", "a 'joints' model and an 'ee_pixel' or 'image' model", modalities,
                                 "e.g. --model analytic:nao_arm:joints --model analytic:nao_arm:ee_pixel"))
    return vision[0]


def goal_poses(robot, n: int, seed: int) -> np.ndarray:
    """(n, Dq) rad held-out goal poses from the robot's sampling ranges."""
    from bodyschema.datagen.samplers import uniform
    return uniform(eval_rng(seed, 0, "targets", TARGET_KEY), robot.sampling_ranges, n)


def simulate(robot, models: Sequence, config: MarkerShiftConfig, q_goal: np.ndarray, offsets: np.ndarray,
             visual_precision: float) -> dict[str, np.ndarray]:
    """One batch of B episodes (goal poses q_goal (B, Dq) rad, marker offsets (B, 3) m) at one visual precision.

    Returns time series, first axis the tick (T+1 samples at t = k/rate s): "t" (T+1,), "q"/"belief" (T+1, B, Dq)
    rad, "hand_xyz" (T+1, B, 3) m, "hand_px"/"marker_px" (T+1, B, 2) px, and per episode "goal_px" (B, 2) px,
    "goal_xyz" (B, 3) m, "failed" (B,) bool, "reasons" (B,) str.
    """
    from tqdm import tqdm
    substeps = control_substeps(config.control_rate, robot.model.opt.timestep, "control_rate")
    dt = 1.0 / config.control_rate
    ticks, shift_tick = int(round(config.duration / dt)), int(round(config.shift_time / dt))
    vision = vision_modality(models)
    drive = tuple(dict.fromkeys(vision if d in VISUAL else d for d in config.action.drive))   # "ee_pixel" → the seer
    action = replace(config.action, drive=drive)
    controller = VelocityController(models, config.perception, action, precisions={vision: visual_precision})
    arms = ArmBatch(robot, q_goal, hold="gravity", marker_offsets=offsets)
    low, high = robot.model.actuator_ctrlrange.T
    goal_xyz = arms.ee_xyz
    goal_px = robot.project(goal_xyz)                                             # (B, 2) px
    goal = {"ee_pixel": goal_px, "joints": q_goal.copy()}.get(config.goal)
    goal = torch.from_numpy(sense(robot, "image", q_goal) if goal is None else goal)
    controller.reset(q_goal, {config.goal: goal})
    known = [m.modality for m in models]
    names = ("q", "belief", "hand_xyz", "hand_px", "marker_px")
    series = {k: [] for k in names}
    for k in tqdm(range(ticks + 1), desc=f"marker shift Π_v={visual_precision:g}", disable=not config.progress):
        arms.shifted[:] = k >= shift_tick
        q, hand, marker = arms.q, arms.ee_xyz, arms.marker_xyz
        obs = sense_all(robot, known, q, xyz=marker, marker_offsets=arms.shown_offsets)   # the seen marker
        marker_px = obs["ee_pixel"].numpy() if "ee_pixel" in obs else sense(robot, "ee_pixel", q, xyz=marker)
        for name, value in zip(names, (q, controller.belief, hand, robot.project(hand), marker_px)):
            series[name].append(value)
        if k == ticks:
            break
        velocity = controller.act(obs, dt)                                        # (B, Dq) rad/s
        arms.step(np.clip(arms.ctrl + velocity * dt, low, high), substeps)        # servo targets += a·Δt
    out = {name: np.stack(v) for name, v in series.items()}
    failed = controller.failed | arms.failed
    reasons = [c or a or "" for c, a in zip(controller.reasons, arms.reasons)]
    out.update(t=np.arange(ticks + 1) * dt, goal_px=goal_px, goal_xyz=goal_xyz, failed=failed,
               reasons=np.array(reasons), shift_tick=np.array(shift_tick))
    return out


def run_marker_shift(config: MarkerShiftConfig = MarkerShiftConfig(), models: Sequence | None = None
                     ) -> dict[str, Path]:
    """Every shift × visual precision on the same held-out goal poses; writes tables and plots to a new run folder
    under config.out and logs one MLflow run. Returns name → Path of what it wrote."""
    models = resolve_models(config.models, DEFAULT_MODELS, config.tracking_uri, models)
    vision = vision_modality(models)
    robot = load_robot(models)
    q_goal = goal_poses(robot, config.trials, config.seed)                     # (E, Dq) rad
    shifts = [s for s in config.shifts for _ in range(config.trials)]          # episode i: shift of row i
    q0 = np.tile(q_goal, (len(config.shifts), 1))                                # (S·E, Dq) rad
    offsets = marker_offsets(shifts, config.offset)                              # (S·E, 3) m, hand frame
    jac_px = robot.project_jacobian(robot.fk(q0)) @ robot.jacobian(q0)           # (S·E, 2, Dq) px/rad, true
    joints = next(m for m in models if m.modality == "joints")
    pi_q = dict(config.perception.precisions).get("joints")
    pi_q = float(joints.precision(torch.from_numpy(q_goal)).mean()) if pi_q is None else float(pi_q)
    rows, batches = [], {}
    for precision in config.visual_precisions:
        series = simulate(robot, models, config, q0, offsets, precision)
        k = int(series["shift_tick"])
        seen = series["marker_px"][k] - series["hand_px"][k]                     # (S·E, 2) px
        predicted = report.predicted_correction(jac_px, seen, precision, pi_q) if vision == "ee_pixel" \
            else np.full(len(seen), np.nan)                                      # the theory is in px⁻²
        rows += report.episode_rows(series, shifts, precision, predicted)
        batches[precision] = series
    return report.write_all(config, new_run(config), robot, models, rows, batches, shifts)
