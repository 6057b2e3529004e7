"""What a `Perception` runs: `PerceptionConfig`, the knobs every update shares, with each update's own knobs in one
group (`FlowSettings`, `LMSettings`, `AdamSettings`), and `resolve`, the one place that turns "auto" into an update.

"auto" is decided here, from the models a perception is given, for every caller: the method is "adam+lm" at order 0
with an image model (its F has shallow local minima that Gauss–Newton jumps land in; bench/aif.py [2]), else "flow"
(Gauss–Newton descent: exact in ~5–20 steps on kinematics); the flow's step control is "descent" at order 0 (F is
then a Lyapunov function of the flow: monotone, no jitter at the noise floor), "none" above. A warm perception (a few
updates per control tick or frame from the last belief: action, the tracker) runs the flow without descent control:
LM and Adam would restart their step sizes every tick, and a moving attractor makes a step that raises F the loop
working, not a step to undo. Whether a model sees images is asked of its modality's record (base/modalities.py).
The CLI spells every knob flat (`--perception.dt`, `--perception.lr`): the groups carry no prefix of their own.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Annotated

from bodyschema.aif import descent
from bodyschema.aif.priors import PRIORS
from bodyschema.base import modalities as modality_table
from bodyschema.cli_marks import Ungrouped
from bodyschema.errors import must_be

INTEGRATORS = ("local_linear", "implicit", "euler")
STEP_CONTROLS = ("auto", "descent", "none")
METHODS = ("flow", *descent.DESCENT_METHODS)


_log = logging.getLogger(__name__)


def _positive(settings, *names: str) -> None:
    for name in names:
        if not getattr(settings, name) > 0:
            raise ValueError(must_be(name, "positive", getattr(settings, name)))


@dataclass(frozen=True)
class FlowSettings:
    """method "flow": generalized filtering (perception.py)."""

    dt: float = 1e3                # s; local_linear is stable for any Δt; Δt·k·λ ≫ 1 → Gauss–Newton steps
    k_z: float = 1.0               # gain on ∂F/∂μ̃
    integrator: str = "local_linear"   # "local_linear" | "implicit" | "euler" (generalized.py)
    # "descent": a step that raises F is undone and that trial's Δt shrinks (order 0); "none": every step is taken;
    # "auto": descent at order 0 (the default of `evaluate levels`: monotone, no jitter at the noise floor), none above
    step_control: str = "auto"
    divergence_step: float = 1e3   # rad; an Euler step larger than this marks the trial diverged
    divergence_ratio: float | None = 100.0   # E growing this much above max(E_start, 1) marks it diverged

    def __post_init__(self):
        _positive(self, "dt", "k_z", "divergence_step")
        if self.integrator not in INTEGRATORS:
            raise ValueError(must_be("integrator", f"one of {INTEGRATORS}", self.integrator))
        if self.divergence_ratio is not None and not self.divergence_ratio > 1:
            raise ValueError(must_be("divergence_ratio", "greater than 1 or None", self.divergence_ratio))
        if self.step_control not in STEP_CONTROLS:
            raise ValueError(must_be("step_control", f"one of {STEP_CONTROLS}", self.step_control))


@dataclass(frozen=True)
class LMSettings:
    """method "lm" (and the second half of "adam+lm"): Levenberg–Marquardt (descent.py)."""

    damping: float = 1.0           # lm: initial λ relative to diag H; large = short gradient-like first steps
    trial_derivatives: bool = False   # the derivatives with every trial step, one model call instead of F and then
    # the derivatives where the step is accepted: for a few trials whose steps are mostly accepted (a tracker's
    # restart); a batch's rejected rows would waste theirs

    def __post_init__(self):
        _positive(self, "damping")


@dataclass(frozen=True)
class AdamSettings:
    """methods "adam" and "adam+lm": the adaptive first-order flow (descent.py)."""

    lr: float = 0.02               # adam: initial step per joint, rad
    patience: int = 5              # adam: steps without a new best F before the step halves
    handover: float = 1e-2         # adam+lm: Adam's step (rad) below which LM takes over (one halving of lr)

    def __post_init__(self):
        _positive(self, "lr", "handover")
        if self.patience < 1:
            raise ValueError(must_be("patience", "at least 1", self.patience))


@dataclass(frozen=True)
class PerceptionConfig:
    order: int = 0                 # n: generalized coordinates μ, μ', …, μ^(n); n ∈ {0, 1, 2}
    max_steps: int = 300           # per trial
    # rad (6e-4°); converged when no coordinate moves more in a step: float32 decoders jitter near 1e-6 rad, so a
    # tighter tol never stops them
    tol: float = 1e-5
    max_step: float | None = 0.2   # rad; trust region on one step of the joints (None: off)
    prior: str = "none"            # "none" | "damping" | "attractor" (priors.py)
    prior_precision: float = 1.0   # Π_z, same for every joint and order
    attractor_gain: float = 1.0    # β in f(μ) = β Jᵀ (x_d − g(μ)): Π_goal = β I
    # Π_goal per goal modality instead of β, for goals of several modalities in their own units (e.g. a pixel goal with
    # a joint-space depth cue): f = Σ_goals Jᵀ Π (x_d − g)
    goal_precisions: tuple[tuple[str, float], ...] = ()
    precisions: tuple[tuple[str, float], ...] = ()   # per-modality overrides, e.g. (("ee_xyz", 1e4),)
    precision_update: str = "step"  # "step": Π from model.precision(μ) at every step; "initial": at μ0 only
    record: bool = False           # keep the trajectory of μ̃, F and the prediction errors
    # lm, adam: steps between two reads of whether a trial stopped (a host sync on a GPU); > 1: stopped trials stay in
    # the batch, masked, and LM takes each trial's derivatives with it (an accepted step by a mask: no read-back inside
    # the loop). A float32 network may round the others' rows differently in the larger batch, which the descent can
    # amplify (measured K=4, 16×16 decoder: ≤ 4.9e-5 rad at 500 trials, up to 9.7e-3 rad at 50): 1, exact, unless a
    # read-back costs (a GPU)
    check_every: int = 1
    # "flow": generalized filtering; order 0 only: "lm" (Levenberg–Marquardt), "adam" (adaptive first-order flow) or
    # "adam+lm" (Adam, then LM once in a basin); "auto": adam+lm at order 0 with an image model, else flow
    method: str = "auto"
    flow: Annotated[FlowSettings, Ungrouped()] = FlowSettings()   # the flow's integrator, step control, divergence
    lm: Annotated[LMSettings, Ungrouped()] = LMSettings()
    adam: Annotated[AdamSettings, Ungrouped()] = AdamSettings()

    @property
    def descends(self) -> bool:
        """Whether flow steps are under descent control ("auto" resolved by the order)."""
        return self.flow.step_control == "descent" or (self.flow.step_control == "auto" and self.order == 0)

    def __post_init__(self):
        _positive(self, "prior_precision", "attractor_gain")
        if not self.tol >= 0:
            raise ValueError(must_be("tol", "positive", self.tol))
        if self.order not in (0, 1, 2):
            raise ValueError(must_be("order", "0, 1 or 2", self.order))
        if self.max_steps < 1:
            raise ValueError(must_be("max_steps", "at least 1", self.max_steps))
        if self.check_every < 1:
            raise ValueError(must_be("check_every", "at least 1", self.check_every))
        if self.prior not in PRIORS:
            raise ValueError(must_be("prior", f"one of {PRIORS}", self.prior))
        if self.max_step is not None and not self.max_step > 0:
            raise ValueError(must_be("max_step", "positive or None", self.max_step))
        if self.flow.step_control == "descent" and self.order > 0:
            raise ValueError(must_be("step_control", "'none' when order > 0", self.flow.step_control,
                                     "With generalized motion the Dμ̃ term makes F no Lyapunov function of the flow."))
        if self.method not in ("auto", *METHODS):
            raise ValueError(must_be("method", f"one of {('auto', *METHODS)}", self.method))
        if self.method not in ("auto", "flow") and self.order > 0:
            raise ValueError(must_be("method", "'flow' when order > 0", self.method,
                                     "lm and adam minimise F at order 0 (static perception)."))
        if self.precision_update not in ("step", "initial"):
            raise ValueError(must_be("precision_update", "'step' or 'initial'", self.precision_update))


DEFAULTS = PerceptionConfig()           # the default of every `config` argument (frozen: one instance serves all)


def is_image(modality: str) -> bool:
    """Whether `modality` is a camera's frames, asked of its record; a modality outside the table is not."""
    return modality_table.is_image(modality)


def resolve(config: PerceptionConfig, modalities: Iterable[str], warm: bool = False) -> PerceptionConfig:
    """config with "auto" replaced by the update for models of these modalities; warm: for a few updates per tick or
    frame from the last belief (module docstring)."""
    method, control, modalities = config.method, config.flow.step_control, set(modalities)
    if method == "auto":
        method = "adam+lm" if not warm and config.order == 0 and any(map(is_image, modalities)) else "flow"
    if control == "auto":
        control = "descent" if not warm and config.descends else "none"
    if "auto" in (config.method, config.flow.step_control):
        _log.debug("perception of %s: method %s → %s, step control %s → %s", "+".join(sorted(modalities)),
                   config.method, method, config.flow.step_control, control)   # "auto" shown as what it became
    return replace(config, method=method, flow=replace(config.flow, step_control=control))
