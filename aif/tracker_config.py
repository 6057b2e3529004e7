"""A tracker's configuration and what its per-frame budget of model evaluations buys (aif/tracker.py runs it)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from bodyschema.aif.perception_config import FlowSettings, LMSettings, PerceptionConfig, resolve
from bodyschema.errors import must_be

RESTARTS = ("auto", "guess", "multistart")
GUESSES = ("auto", "reading", "encoder")
# (evaluations before the first update, worst case per update) of the descents (descent.py: LM evaluates F, then the
# derivatives where a step is accepted; adam+lm runs both with the same max_steps)
DESCENT_COST = {"lm": (1, 2), "adam": (1, 1), "adam+lm": (2, 3)}
RESTART = PerceptionConfig(max_steps=2, lm=LMSettings(trial_derivatives=True))   # TrackerConfig.restart_perception

@dataclass(frozen=True)
class TrackerConfig:
    perception: PerceptionConfig = resolve(PerceptionConfig(tol=1e-4, flow=FlowSettings(step_control="descent")), (),
                                           warm=True)
    # per frame (order 0): a warm perception's update (perception_config.resolve: Gauss–Newton steps of the
    # local-linear flow), here under descent control: a step that raises F is undone and the next one shorter.
    # Measured (nao_arm, 30 Hz, README-recipe decoder and encoder, 20 s): 0.70° mean joint error and 3 % of frames
    # restarted, against 0.86° and 8 % with every undamped step taken (step_control "none")
    budget: int = 5                 # model evaluations per stream and frame, an encoder proposal's 2 included
    # (with an encoder and an image model: the proposal and three descent-controlled steps; else five steps)
    budget_ms: float | None = None  # per frame, on top of `budget`; None: off (timing makes runs irreproducible)
    order: int = 1                  # motion of the belief: 0 still, 1 velocity, 2 velocity and acceleration
    motion_gain: float = 0.5        # α of the α-β filter: the share of a frame's finite difference taken into μ'
    lost_threshold: float | None = None   # F above this: lost track; None: set by `calibrate`, else never lost
    lost_quantile: float = 0.99     # calibrate: the quantile of F at the true poses …
    lost_slack: float = 1.0         # … plus this many times its distance to the median (F's spread)
    guess: str = "auto"             # the frame's direct guess of the pose, a start for the proposal and the restarts:
    # "reading" (a joints sensor's own reading, where one is perceived), "encoder" (the image encoder's), "auto":
    # the reading where there is one, else the encoder's. The reading is as far from the truth as its noise (1°: a
    # mean of 0.8°), the encoder's guess ~2.3° on nao_arm, with heavier tails
    restart: str = "auto"           # "guess" (from the frame's guess), "multistart", "auto": the guess where there is
    # one, else multistart
    restart_perception: PerceptionConfig = RESTART   # a restart's update ("auto": Adam then LM with an image model)
    # One stream's LM steps are mostly accepted, so each trial brings its derivatives. Adam then LM as in the levels,
    # monotone in F, where undamped Gauss–Newton steps bounce (1.7° against 2.1° on nao_arm at 30 Hz). 2 steps each:
    # a restart costs ≤ 8 evaluations, and its frame stays within a p95 of 20 ms (measured, nao_arm 30 Hz, 30 s:
    # 3 steps 0.81° mean error, restarted frames 24 ms; 2 steps 0.85°, 19 ms; Adam alone, 3 steps: 0.94°, 13 ms)
    restart_starts: int = 8         # multistart: starts per lost stream (tracked, predicted, uniform draws)
    settle_quantile: float | None = 0.5   # skip the updates where F at the start < this quantile of F at the truths
    # of the calibration frames (F at the start is known from the proposal: with an encoder and an image model). A
    # start as good as a typical truth is not improved by steps that jitter at the noise floor. Measured on nao_arm at
    # 30 Hz: None 0.60°, 0.5 0.62° (20 s; 12 % fewer evaluations); 0.75 saves 6 % more but lost 0.04° and the 3-frame
    # recovery on bench/tracking.py's 60 s (0.98° vs 0.94°, longest lost track 12 vs 3 frames)
    consistency: bool = True        # with several modalities, `calibrate` also sets a threshold per low-dimensional
    # sensor (joints, ee; ≤ 64 outputs) on its own ½ εᵀΠε at the truth, and a belief one of them contradicts is lost
    # too, even where F is not: an image's thousands of pixels, weighted as independent, can favour a wrong pose as
    # much as the joint encoders penalise it (nao_arm fused with joints: 13 frames 10° off at F equal to F at the
    # truth); a restart's candidate the sensors accept then beats one they reject
    consistency_slack: float = 3.0  # a sensor's threshold: its lost_quantile plus this many times its distance to the
    # median. Measured (nao_arm fused with joints, bench/tracking.py, 60 s at 30 Hz): 3.0 restarts 11 % of frames,
    # 0.77° mean error, lost track ≤ 2 frames; 1.0: 16 %, 0.74°, ≤ 2 frames (the restarted frames set the p95: 1 ms
    # more); without the test: 7 %, 0.88°, 13 frames lost (that ambiguity's ½ εᵀΠε ≈ 117 is far above either)
    proposals: bool = True          # where there is a guess, it competes with the predicted belief every frame, the
    # lower F starting the updates (2 F evaluations of the budget): a babbling arm moves up to ~20° between frames at
    # 30 Hz, farther than an image F's basin around the predicted pose

    def __post_init__(self):
        if self.perception.order != 0:
            raise ValueError(must_be("perception.order", "0 (the tracker holds the motion: `order`)",
                                     self.perception.order))
        if self.order not in (0, 1, 2):
            raise ValueError(must_be("order", "0, 1 or 2", self.order))
        if not (isinstance(self.budget, int) and self.budget >= 1):
            raise ValueError(must_be("budget", "a whole number of model evaluations ≥ 1", self.budget))
        if self.budget_ms is not None and not self.budget_ms > 0:
            raise ValueError(must_be("budget_ms", "a positive duration in ms or None", self.budget_ms))
        if not 0 < self.motion_gain <= 1:
            raise ValueError(must_be("motion_gain", "in (0, 1]", self.motion_gain))
        if self.lost_threshold is not None and not math.isfinite(self.lost_threshold):
            raise ValueError(must_be("lost_threshold", "a finite free energy or None", self.lost_threshold))
        if self.settle_quantile is not None and not 0 < self.settle_quantile < 1:
            raise ValueError(must_be("settle_quantile", "in (0, 1) or None", self.settle_quantile))
        if not 0 < self.lost_quantile < 1 or not self.lost_slack >= 0:
            raise ValueError(must_be("lost_quantile, lost_slack", "in (0, 1) and ≥ 0",
                                     (self.lost_quantile, self.lost_slack)))
        if self.restart not in RESTARTS:
            raise ValueError(must_be("restart", f"one of {RESTARTS}", self.restart))
        if self.guess not in GUESSES:
            raise ValueError(must_be("guess", f"one of {GUESSES}", self.guess))
        if self.restart_perception.order != 0 or self.restart_starts < 2:
            raise ValueError(must_be("restart_perception.order, restart_starts", "0 and ≥ 2",
                                     (self.restart_perception.order, self.restart_starts)))


DEFAULTS = TrackerConfig()            # the default of `Tracker`'s config (frozen: one instance serves all)


def steps_within(config: PerceptionConfig, evaluations: int) -> int:
    """max_steps of a resolved perception config whose model evaluations per stream fit `evaluations` (worst case).
    The flow evaluates once per step, plus F at the end without descent control (flow.py)."""
    if config.method == "flow":
        return max(0, evaluations - (0 if config.descends else 1))
    first, per_step = DESCENT_COST[config.method]
    return max(0, (evaluations - first) // per_step)


def least_steps(config: PerceptionConfig) -> int:
    """The max_steps that move a belief once: under descent control a step is accepted when the next is evaluated."""
    return 2 if config.method == "flow" and config.descends else 1
