"""Closed-loop reaching: active inference against a PD baseline on N random reachable targets.

Targets are joint poses drawn uniformly from the robot's sampling ranges (a seed stream of their own, held out
from datagen and from the levels benchmark); the goal is what the goal sensor would read at that pose (so it
is reachable by construction): an image (nao_arm with an image model, rendered at the target pose and scaled
as training images), an ee pixel, an ee position (panda) or joint angles. Every episode starts at rest at
another random pose, with the belief at that pose.
The controllers follow what the robot's actuators take (`robot.actuation`, its record's [reaching] actuators):
  position (nao_arm, planar2)  AIF: `aif.action.VelocityController` velocity commands integrated into the servo
                      targets; baseline: the servos commanded to the target's joint pose (its true inverse kinematics)
                      plus the servo's gravity feed-forward, from the model under Earth gravity (servo_baseline.py).
  torque (panda)      AIF: the same velocity controller on the arm's joint impedance servo (setpoint + velocity
                      reference, the baseline's PD + gravity compensation; `--panda-controller aic`: the torque AIC,
                      `aif.aic.AICController`); baseline: PD + gravity compensation on the target pose.
The velocity controller's gains are per robot (record [reaching.action]) unless --action.* is given:
K = k_a·Δt·Π_joints must stay below what the servo can follow (planar2's soft servos lag ≈ 0.1 s).
Metrics per episode (report.py): success (simulator ee within `success_mm` of the target's ee at the
end), final ee error, final joint error, time to reach (first time within success_mm and staying), the error
in the goal's own space (px, mm, deg or image MSE) and failures with their reasons.
Goal inference (goal_pose.py, `--goal-inference`; auto: image and ee_xyz goals): before the episode the AIF
perceives each goal's pose in imagination, from several starts (an image encoder's guess with `--encoder`), and
reaches for that pose through its joints model.
An ee pixel goal fixes the ray through the target, not its depth: with the default nao_arm models the AIF meets
the pixel goal far more often than the 1 cm (3-D) criterion; `--depth-cue-deg σ` adds the depth as a second goal,
the target's joint pose seen through σ° of noise (Π = 1/σ²), fused with the pixel goal by the same attractor.
With an image model every control tick renders B images (wall times per controller: the run's summary table).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from bodyschema.aif.action import ActionConfig, VelocityController
from bodyschema.aif.aic import AICController
from bodyschema.aif.aic_config import AICConfig
from bodyschema.aif.goal_inference import goal_precision
from bodyschema.aif.perception_config import FlowSettings, PerceptionConfig
from bodyschema.base.modalities import is_image
from bodyschema.control.loop import ImpedancePolicy, ServoPolicy, TorquePolicy, VelocityPolicy, rollout
from bodyschema.control.pd import PDController
from bodyschema.control.robot_defaults import reaching_defaults
from bodyschema.control.sim import control_substeps
from bodyschema.control.targets import in_view_targets
from bodyschema.datagen.body.record import check_robot_ref
from bodyschema.datagen.samplers import uniform
from bodyschema.errors import must_be
from bodyschema.evaluation.core.config import TrialsConfig
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.seeds import REACHING, eval_rng
from bodyschema.evaluation.core.sensing import Sensors
from bodyschema.evaluation.core.specs import load_robot, models_field, resolve_encoder, resolve_models, robot_name
from bodyschema.evaluation.reaching import goal_pose, report as reaching_report
from bodyschema.evaluation.reaching.goals import builtin_sensors, check_goal, goal_names, make_goal
from bodyschema.evaluation.reaching.servo_baseline import servo_targets

PANDA_CONTROLLERS = ("velocity", "aic")


@dataclass(frozen=True)
class ReachingRunConfig(TrialsConfig):
    """What reaching and its robustness sweeps share: the robot, models, goal, episodes and controllers."""

    out: Path = Path("results/reaching")             # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-reaching"          # the MLflow experiment
    robot: str = "nao_arm"                 # "nao_arm" | "planar2" (servos) | "panda" (torques) | a model file
    models: models_field("the robot's analytic defaults (nao_arm: ee_pixel + joints; panda: ee_xyz)") = ()
    goal: str = "auto"                     # goal modality; auto: image > ee_xyz > ee_pixel > joints among the models
    trials: int = 100                      # random reachable targets (episodes per controller)
    duration: float | None = None          # s per episode; None: the robot record's [reaching] duration_s
    control_hz: float | None = None        # must divide into whole MuJoCo steps; None: the record's control_hz
    action: ActionConfig = ActionConfig()  # the velocity controller; left at its default: the robot record's
    perception: PerceptionConfig = PerceptionConfig(flow=FlowSettings(step_control="none"))   # servo robots: per tick
    aic: AICConfig = AICConfig()           # torque robots: the AIC's gains and precisions
    # torque robots: "velocity" (the velocity controller on the arm's joint impedance servo, like nao_arm's servos) |
    # "aic" (torques, aif/aic.py)
    panda_controller: str = "velocity"
    success_mm: float = 10.0               # success: final simulator ee error below this
    pixel_tolerance: float = 1.0           # px; goal-space success of an ee_pixel goal
    # image goal success: the median MSE of a 1 cm ee offset (nao_arm, its hand, 56×80; 200 poses: 0.0105, 5 mm: 0.0043)
    image_mse_threshold: float = 1e-2
    image_size: tuple[int, int] | None = None   # robot camera (H, W); default: the image model's, else the robot's
    # > 0: a second goal, the target's joint pose seen through σ° of noise (Π = 1/σ²), the depth an ee_pixel goal leaves
    # open; needs a joints model
    depth_cue_deg: float = 0.0
    # targets and starts uniform in the middle `spread` of each joint's sampling range: a goal across a joint limit
    # stalls descent there
    spread: float = 1.0
    goal_inference: str = "auto"           # imagine each goal's pose, then reach it: auto (image, ee_xyz) | on | off
    goal_starts: int = 8                   # starts of that search: the start pose, the encoder's guess, random
    encoder: str | None = None             # an image encoder spec: its guess starts an image goal's search

    def __post_init__(self):
        super().__post_init__()
        if check_robot_ref(self.robot):
            raise ValueError(check_robot_ref(self.robot))
        if not 0 < self.spread <= 1:
            raise ValueError(must_be("spread", "in (0, 1] (a fraction of each joint's sampling range)", self.spread))
        if self.panda_controller not in PANDA_CONTROLLERS:
            raise ValueError(must_be("panda_controller", f"one of {PANDA_CONTROLLERS}", self.panda_controller))
        if self.goal_inference not in goal_pose.MODES:
            raise ValueError(must_be("goal_inference", f"one of {goal_pose.MODES}", self.goal_inference))
        if self.goal not in ("auto", *goal_names()):
            raise ValueError(must_be("goal", f"'auto' or one of {goal_names()}", self.goal))

    @property
    def default_models(self) -> tuple[str, ...]:
        return reaching_defaults(self.robot).models

    @property
    def action_config(self) -> ActionConfig:
        """config.action, or the robot's tuned one when config.action is left at the default."""
        tuned = reaching_defaults(self.robot).action
        return tuned if self.action == ActionConfig() and tuned is not None else self.action

    @property
    def rate(self) -> float:
        return reaching_defaults(self.robot).control_hz if self.control_hz is None else self.control_hz

    @property
    def seconds(self) -> float:
        return reaching_defaults(self.robot).duration_s if self.duration is None else self.duration


@dataclass(frozen=True)
class ReachingConfig(ReachingRunConfig):
    """Closed-loop AIF reaching to random reachable goals against the PD baseline."""

    noise: tuple[tuple[str, float], ...] = ()   # observation noise σ per modality (rad, m, px, intensity)
    broken: tuple[str, ...] = ()           # modalities whose precision is 0 (a dead sensor)
    frozen: tuple[str, ...] = ()           # modalities whose stream is frozen at its first reading
    baseline: bool = True                  # also run the PD baseline
    path_plots: int = 6                    # targets drawn in the image-plane path plot


@dataclass
class Episodes:
    q_target: np.ndarray                   # (N, Dq) rad
    q_start: np.ndarray                    # (N, Dq) rad
    goal: dict[str, torch.Tensor]          # one modality → (N, *out)
    target_xyz: np.ndarray                 # (N, 3) m
    extra: dict = field(default_factory=dict)


# ---- episodes (what may be a goal and whether it is reachable: goals.py) ------------------------------------
def goal_modality(config: ReachingRunConfig, models, robot) -> str:
    names = [m.modality for m in models] + builtin_sensors(robot)
    if config.goal != "auto":
        if config.goal not in names:
            raise ValueError(must_be("goal", f"the modality of one of the models {names}", config.goal))
        return config.goal
    return next(g for g in goal_names() if g in names)


def spread_ranges(robot, spread: float) -> np.ndarray:
    """The middle `spread` of each joint's sampling range. # (Dq, 2) rad"""
    ranges = np.asarray(robot.sampling_ranges, dtype=np.float64)
    mid, half = ranges.mean(1), 0.5 * (ranges[:, 1] - ranges[:, 0])
    return np.stack([mid - spread * half, mid + spread * half], axis=1)


def make_episodes(config: ReachingConfig, robot, modality: str, output_shape) -> Episodes:
    ranges = robot.sampling_ranges if config.spread == 1 else spread_ranges(robot, config.spread)
    targets_rng, starts_rng = (eval_rng(config.seed, None, p, stream=REACHING) for p in ("targets", "starts"))
    q_target = in_view_targets(targets_rng, robot, config.trials, ranges)
    q_start = uniform(starts_rng, ranges, config.trials)
    goal = make_goal(robot, modality, q_target)
    check_goal(robot, modality, goal, output_shape)
    episodes = Episodes(q_target, q_start, {modality: goal}, robot.fk(q_target))
    if config.depth_cue_deg > 0:
        sigma = np.deg2rad(config.depth_cue_deg)
        cue_rng = eval_rng(config.seed, None, "cue", stream=REACHING)
        cue = q_target + sigma * cue_rng.standard_normal(q_target.shape)   # (N, Dq) rad
        episodes.goal["joints"] = torch.from_numpy(np.clip(cue, *robot.joint_limits.T))
        episodes.extra["goal_precisions"] = {"joints": 1.0 / sigma ** 2}
    return episodes


# ---- controllers ------------------------------------------------------------------------------------------
def aif_policy(config: ReachingConfig, models, robot, goal_precisions: dict[str, float] | None = None):
    """goal_precisions: Π_goal per goal modality for the velocity controller (a depth cue's)."""
    precisions = {m: 0.0 for m in config.broken}
    if robot.actuation == "position":
        return VelocityPolicy(VelocityController(models, config.perception, config.action_config, precisions),
                              goal_precisions)
    if "joints" in config.broken:
        raise ValueError(must_be("broken", "extra sensors only on the panda (its joint sensor feeds the servo and "
                                 "the AIC)", config.broken))
    if config.panda_controller == "velocity":
        controller = VelocityController(models, config.perception, config.action_config, precisions)
        return ImpedancePolicy(controller, PDController(robot), tuple(robot.joint_limits.T), goal_precisions)
    aic = replace(config.aic, precisions=tuple((m, p) for m, p in config.aic.precisions if m not in precisions)
                  + tuple(precisions.items()))
    extra = [m for m in models if m.modality != "joints"]
    return TorquePolicy(AICController(extra, aic, np.abs(robot.model.actuator_ctrlrange[:, 1])))


def goal_inference_on(config: ReachingRunConfig, modality: str, names: list[str], robot) -> bool:
    """Whether the AIF reaches for the goal's imagined pose: config.goal_inference for this goal, given a joints
    model to reach through and a velocity controller ("auto" quietly falls back to the goal's own attractor)."""
    if not goal_pose.wanted(config.goal_inference, modality) or modality == "joints":
        return False
    able = "joints" in names and (robot.actuation == "position" or config.panda_controller == "velocity")
    if not able and config.goal_inference == "on":
        raise ValueError(must_be("goal_inference", "'auto' or 'off' without a joints model and the velocity "
                                 "controller", config.goal_inference,
                                 "Add analytic:<robot>:joints (the imagined pose is reached through it)."))
    return able


def aif_goal(config: ReachingRunConfig, models, episodes: Episodes) -> tuple[dict, dict | None]:
    """What the AIF controller reaches for: the imagined pose when goal inference ran (a joint goal that outweighs
    the senses by β, aif.goal_inference.goal_precision), else the goal itself (with a depth cue's precision).
    → goal, Π_goal per modality or None"""
    imagined = episodes.extra.get("imagined")
    if imagined is None:
        return episodes.goal, episodes.extra.get("goal_precisions")
    pi = goal_precision(models, torch.from_numpy(episodes.q_start), config.action_config.attractor_gain,
                        {**dict(config.perception.precisions), **{m: 0.0 for m in config.broken}})
    return {"joints": imagined.q.clone()}, {"joints": pi}


def baseline_policy(config: ReachingConfig, robot, episodes: Episodes):
    if robot.actuation == "position":
        return ServoPolicy(servo_targets(robot, episodes.q_target))        # the target pose + gravity feed-forward
    return TorquePolicy(PDController(robot), goal={"joints": episodes.q_target})


# ---- the benchmark ----------------------------------------------------------------------------------------
def run_reaching(config: ReachingConfig = ReachingConfig(), models=None) -> dict[str, Path]:
    """AIF (and the PD baseline) on config.trials episodes; writes tables and plots to a new run folder under
    config.out and logs one MLflow run."""
    models = resolve_models(config.models, config.default_models, config.tracking_uri, models)
    robot, models, modality, episodes, results, walls = simulate(config, models)
    return reaching_report.write_all(config, new_run(config), robot, models, modality, episodes, results, walls)


def simulate(config: ReachingConfig, models=None):
    """Run every controller on the episodes. → robot, models, goal modality, episodes, {name: Rollout},
    {name: wall time s}."""
    robot, models, modality, episodes, sensed = prepare(config, models)
    substeps = control_substeps(config.rate, robot.model.opt.timestep)
    ticks = int(round(config.seconds * config.rate))
    goals, precisions = aif_goal(config, models, episodes)
    policies = {"aif": aif_policy(config, models, robot, precisions)}
    if config.baseline:
        policies["pd"] = baseline_policy(config, robot, episodes)
    results, walls = {}, {}
    for name, policy in policies.items():
        sensors = Sensors(sensed if name == "aif" else (), dict(config.noise), frozenset(config.frozen),
                          eval_rng(config.seed, None, "noise", stream=REACHING))   # the baselines sense the true state
        start = time.perf_counter()
        goal = {k: v.clone() for k, v in (goals if name == "aif" else episodes.goal).items()}
        results[name] = rollout(robot, policy, episodes.q_start, goal, episodes.target_xyz, sensors, ticks,
                                substeps, config.progress, desc=f"reaching {name}")
        walls[name] = time.perf_counter() - start
    walls["aif"] += episodes.extra.get("imagined_wall_s", 0.0)            # its imagination is part of its work
    return robot, models, modality, episodes, results, walls


def prepare(config: ReachingConfig, models=None):
    """Resolve and check the models, load the robot, build the episodes. → robot, models, goal modality,
    episodes, sensed modalities."""
    models = resolve_models(config.models, config.default_models, config.tracking_uri, models)
    name = robot_name(config.robot)
    if any(m.body.robot != name for m in models):
        bad = next(m for m in models if m.body.robot != name)
        raise ValueError(must_be(f"{bad.modality} model body", f"of robot {name!r}", bad.body.robot,
                                 "Pass models of the benchmark's robot (or change --robot)."))
    robot = load_robot(models, config.image_size, actuators=reaching_defaults(config.robot).actuators)
    names = [m.modality for m in models]
    for what in ("broken", "frozen"):
        unknown = sorted(set(getattr(config, what)) - set(names) - set(builtin_sensors(robot)))
        if unknown:
            raise ValueError(must_be(what, f"modalities of the models {names}", unknown))
    modality = goal_modality(config, models, robot)
    if config.depth_cue_deg > 0 and (modality == "joints" or "joints" not in names or robot.actuation != "position"
                                     and config.panda_controller != "velocity"):
        raise ValueError(must_be("depth_cue_deg", "0 unless the goal is not joints and a joints model is fused "
                                 "(velocity controller)", config.depth_cue_deg, "Add analytic:<robot>:joints."))
    shape = (robot.dq,) if modality == "joints" else next(m.output_shape for m in models if m.modality == modality)
    infer_pose = goal_inference_on(config, modality, names, robot)
    if config.encoder is not None and not (infer_pose and is_image(modality)):
        raise ValueError(must_be("encoder", "None unless goal inference runs on an image goal", config.encoder,
                                 "Pass an image model and leave --goal-inference at auto or on."))
    encoder = resolve_encoder(config.encoder, robot, config.tracking_uri) if infer_pose else None
    episodes = make_episodes(config, robot, modality, shape)
    if infer_pose:
        start = time.perf_counter()
        ranges = robot.sampling_ranges if config.spread == 1 else spread_ranges(robot, config.spread)
        imagined_rng = eval_rng(config.seed, None, "imagined", stream=REACHING)
        episodes.extra["imagined"] = goal_pose.imagine(config, models, robot, episodes, imagined_rng, ranges, encoder)
        episodes.extra["imagined_wall_s"] = time.perf_counter() - start
    sensed = tuple(dict.fromkeys(names + builtin_sensors(robot)))
    unknown = sorted(set(dict(config.noise)) - set(sensed))
    if unknown:
        raise ValueError(must_be("noise modality", f"one of the sensed modalities {list(sensed)}", unknown))
    return robot, models, modality, episodes, sensed
