"""Perception by generalized filtering: a batch of beliefs μ̃ over the joints descends the Laplace free energy.

    dμ̃/dt = Dμ̃ − k_z ∂F/∂μ̃                              (Friston et al. 2010, "Generalised filtering", eq. 5)
    F = Σ_m ½ ε_mᵀ Π_m ε_m + ½ ε_zᵀ Π_z ε_z − ½ ln|Π|      (free_energy.py, priors.py)

Integration: "local_linear" (default) takes Ozaki's step Δt φ₁(Δt 𝓙) u̇ with the Gauss–Newton flow Jacobian
𝓙 = D ⊗ I − k_z H (generalized.py): each step is precision-normalised — a damped Newton step that needs no
tuning of Δt to the sensory precision — and converges in tens of steps; "implicit" is the linearly implicit
Euler step (same limits, a solve instead of an exponential); "euler" is the plain Δt·u̇ of the Pixel-AIF
protocol. With step_control "descent" (order 0: F is then a Lyapunov function of the flow) a step that raises F
is undone and that trial's Δt shrinks ×0.1 (it regrows ×2 on accepted steps, up to config.dt): the Gauss–Newton
step becomes Levenberg–Marquardt-like, monotone, and a trial stops once even a step below `tol` does not
descend, instead of jittering at the float32 noise floor of a learned model. A step of the joints is capped
at `max_step` rad (trust region), the belief is clamped to the joint limits, and every trial stops on its own:
trials that converged (moved < tol) or diverged (F or the step not finite, an Euler step > divergence_step rad, or
the precision-weighted prediction error E = F + ½ln|Π| grown above divergence_ratio · max(E at the start, 1) — an
unstable update bouncing between the joint limits) leave the active batch and are never evaluated again. Batched
and per-trial runs perform the same arithmetic row by row (bit-equal for float64 models; a float32 network may
round differently at another batch size).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from bodyschema.aif import descent
from bodyschema.aif.descent import record_step
from bodyschema.aif.free_energy import (JACOBIAN_MAX_OUTPUTS, check_models, check_observations, model_input,
                                         sensory_terms)
from bodyschema.aif.generalized import implicit_step, local_linear_step, shift, shift_matrix
from bodyschema.aif.priors import PRIORS, attractor, prior_terms
from bodyschema.errors import must_be
from bodyschema.models.contract import as_input

INTEGRATORS = ("local_linear", "implicit", "euler")
STEPS = {"local_linear": local_linear_step, "implicit": implicit_step}
STEP_CONTROLS = ("auto", "descent", "none")
METHODS = ("flow", *descent.DESCENT_METHODS)
DESCENT_SLACK = 1e-7     # relative rise of F still accepted: float32 models evaluate F to ~1e-7
DT_GROW, DT_SHRINK = 2.0, 0.1   # Δt of a trial after an accepted / a rejected step (never above config.dt)


@dataclass(frozen=True)
class PerceptionConfig:
    dt: float = 1e3                # s; local_linear is stable for any Δt; Δt·k·λ ≫ 1 → Gauss–Newton steps
    k_z: float = 1.0               # gain on ∂F/∂μ̃
    order: int = 0                 # n: generalized coordinates μ, μ', …, μ^(n); n ∈ {0, 1, 2}
    max_steps: int = 300           # per trial
    tol: float = 1e-5              # rad (6e-4°); converged when no coordinate moves more in a step: float32
                                   # decoders jitter near 1e-6 rad, so a tighter tol never stops them
    prior: str = "none"            # "none" | "damping" | "attractor" (priors.py)
    prior_precision: float = 1.0   # Π_z, same for every joint and order
    attractor_gain: float = 1.0    # β in f(μ) = β Jᵀ (x_d − g(μ)): Π_goal = β I
    goal_precisions: tuple[tuple[str, float], ...] = ()   # Π_goal per goal modality instead of β, for goals of
                                                          # several modalities in their own units (e.g. a pixel goal
                                                          # with a joint-space depth cue): f = Σ_goals Jᵀ Π (x_d − g)
    integrator: str = "local_linear"
    max_step: float | None = 0.2   # rad; trust region on one step of the joints (None: off)
    divergence_step: float = 1e3   # rad; an Euler step larger than this marks the trial diverged
    divergence_ratio: float | None = 100.0   # E growing this much above max(E_start, 1) marks it diverged
    precisions: tuple[tuple[str, float], ...] = ()   # per-modality overrides, e.g. (("ee_xyz", 1e4),)
    precision_update: str = "step"  # "step": Π from model.precision(μ) at every step; "initial": at μ0 only
    record: bool = False           # keep the trajectory of μ̃, F and the prediction errors
    step_control: str = "auto"     # "descent": a step that raises F is undone and that trial's Δt shrinks (order 0);
                                   # "none": every step is taken; "auto": descent at order 0 (the default of
                                   # `evaluate levels`: monotone, no jitter at the noise floor), none above
    method: str = "flow"           # "flow": generalized filtering (integrator above); order 0 only: "lm"
                                   # (Levenberg–Marquardt), "adam" (adaptive first-order flow) or "adam+lm"
                                   # (Adam, then LM once in a basin): descent.py
    damping: float = 1.0           # lm: initial λ relative to diag H; large = short gradient-like first steps
    lr: float = 0.02               # adam: initial step per joint, rad
    patience: int = 5              # adam: steps without a new best F before the step halves
    handover: float = 1e-2         # adam+lm: Adam's step (rad) below which LM takes over (one halving of lr)

    @property
    def descends(self) -> bool:
        """Whether steps are under descent control ("auto" resolved by the order)."""
        return self.step_control == "descent" or (self.step_control == "auto" and self.order == 0)

    def __post_init__(self):
        for name in ("dt", "k_z", "prior_precision", "attractor_gain", "tol", "divergence_step"):
            value = getattr(self, name)
            if not value > 0 and not (name == "tol" and value == 0):
                raise ValueError(must_be(name, "positive", value))
        if self.order not in (0, 1, 2):
            raise ValueError(must_be("order", "0, 1 or 2", self.order))
        if self.max_steps < 1:
            raise ValueError(must_be("max_steps", "at least 1", self.max_steps))
        if self.prior not in PRIORS:
            raise ValueError(must_be("prior", f"one of {PRIORS}", self.prior))
        if self.integrator not in INTEGRATORS:
            raise ValueError(must_be("integrator", f"one of {INTEGRATORS}", self.integrator))
        if self.divergence_ratio is not None and not self.divergence_ratio > 1:
            raise ValueError(must_be("divergence_ratio", "greater than 1 or None", self.divergence_ratio))
        if self.max_step is not None and not self.max_step > 0:
            raise ValueError(must_be("max_step", "positive or None", self.max_step))
        if self.step_control not in STEP_CONTROLS:
            raise ValueError(must_be("step_control", f"one of {STEP_CONTROLS}", self.step_control))
        if self.step_control == "descent" and self.order > 0:
            raise ValueError(must_be("step_control", "'none' when order > 0", self.step_control,
                                     "With generalized motion the Dμ̃ term makes F no Lyapunov function of the flow."))
        if self.method not in METHODS:
            raise ValueError(must_be("method", f"one of {METHODS}", self.method))
        if self.method != "flow" and self.order > 0:
            raise ValueError(must_be("method", "'flow' when order > 0", self.method,
                                     "lm and adam minimise F at order 0 (static perception)."))
        for name in ("damping", "lr", "handover"):
            if not getattr(self, name) > 0:
                raise ValueError(must_be(name, "positive", getattr(self, name)))
        if self.patience < 1:
            raise ValueError(must_be("patience", "at least 1", self.patience))
        if self.precision_update not in ("step", "initial"):
            raise ValueError(must_be("precision_update", "'step' or 'initial'", self.precision_update))


@dataclass
class PerceptionResult:
    mu: torch.Tensor               # (B, Dz) rad, final belief (order 0)
    mu_tilde: torch.Tensor         # (B, K, Dz) final belief in generalized coordinates
    steps: torch.Tensor            # (B,) int, updates performed
    converged: torch.Tensor        # (B,) bool
    diverged: torch.Tensor         # (B,) bool
    diverged_step: torch.Tensor    # (B,) int, step at which F or the step went non-finite; −1 if never
    F: torch.Tensor                # (B,) free energy at the final belief (at divergence: the last finite one)
    evaluations: int = 0           # model-evaluation rounds × trials (a round = predict + Jacobian/VJP per model)
    trajectory: dict[str, torch.Tensor] | None = None  # "mu" (T, B, K, Dz), "F" (T, B), "error:<m>" (T, B); NaN once stopped

    @property
    def n_diverged(self) -> int:
        return int(self.diverged.sum())


def as_inputs(named):
    """{name: numpy array or tensor} → {name: tensor}; anything else is left for the checks to judge."""
    return {k: as_input(v) for k, v in named.items()} if isinstance(named, Mapping) else named


class _Cache:
    """F, ∂F/∂μ̃, H and prediction errors at every trial's accepted belief: a rejected step falls back on them."""

    def __init__(self, b: int, n: int, need_h: bool):
        self.free = torch.zeros(b, dtype=torch.float64)
        self.grad = None
        self.hess = torch.zeros(b, n, n, dtype=torch.float64) if need_h else None
        self.errors: dict[str, torch.Tensor] = {}

    def store(self, rows, free, grad, hess, errors):
        if self.grad is None:
            self.grad = torch.zeros(self.free.shape[0], *grad.shape[1:], dtype=grad.dtype)
        self.free[rows], self.grad[rows] = free, grad
        if hess is not None:
            self.hess[rows] = hess
        for name, e in errors.items():
            self.errors.setdefault(name, torch.zeros_like(self.free))[rows] = e

    def merge(self, rows, ok, free, grad, hess, errors):
        """The new terms where the step was accepted (ok), the cached ones where it was rejected."""
        free = torch.where(ok, free, self.free[rows])
        grad = torch.where(ok[:, None, None], grad, self.grad[rows])
        if hess is not None:
            hess = torch.where(ok[:, None, None], hess, self.hess[rows])
        errors = {name: torch.where(ok, e, self.errors[name][rows]) for name, e in errors.items()}
        return free, grad, hess, errors


@dataclass
class _Sensors:                    # what one run needs about its observations, resolved once
    observations: dict[str, torch.Tensor]
    fixed: dict[str, torch.Tensor]            # modality → (B, *out) precision held fixed
    goal: list[tuple[object, torch.Tensor, float]] | None = None   # (model, x_d (B, *out), Π_goal) per modality


class Perception:
    """Batched generalized filtering over any set of SensoryModels of the same body.

    models: one model per modality, all over the same robot and joints (checked).
    precisions: modality → float or tensor (broadcast to (B, *out)) overriding `model.precision`; 0 = broken
        sensor, its observation may then be omitted. Overrides here win over `config.precisions`.
    limits: (low, high) rad per joint; defaults to the models' `body.q_low / q_high`.
    """

    def __init__(self, models: Sequence, config: PerceptionConfig = PerceptionConfig(),
                 precisions: Mapping[str, float | torch.Tensor] | None = None,
                 limits: tuple[Sequence[float], Sequence[float]] | None = None):
        self.models = list(models)
        self.body = check_models(self.models)
        self.config = config
        known = {m.modality for m in self.models}
        merged = {**dict(config.precisions), **dict(precisions or {})}
        for name in merged:
            if name not in known:
                raise ValueError(must_be("precision override key", f"one of the models' modalities {sorted(known)}",
                                         name))
        self.precisions = merged
        low, high = limits if limits is not None else (self.body.q_low, self.body.q_high)
        self.low = torch.as_tensor(low, dtype=torch.float64)
        self.high = torch.as_tensor(high, dtype=torch.float64)
        if self.low.shape != (self.body.latent_dim,) or self.high.shape != self.low.shape:
            raise ValueError(must_be("limits", f"two sequences of {self.body.latent_dim} angles in rad",
                                     (tuple(self.low.shape), tuple(self.high.shape))))

    @property
    def latent_dim(self) -> int:
        return self.body.latent_dim

    # ---- public -----------------------------------------------------------------------------------------
    def infer(self, observations: Mapping[str, torch.Tensor], mu0: torch.Tensor,
              goal: Mapping[str, torch.Tensor] | None = None) -> PerceptionResult:
        """Run inference for B trials. observations: modality → (B, *out); mu0: (B, Dz) or (B, K, Dz) rad.

        goal: for prior "attractor", modality → (B, *out) target x_d in that model's output space (one or more:
            their attractors add up, each with Π_goal from config.goal_precisions, else attractor_gain).
        Inference is deterministic: no generator is needed. numpy arrays are accepted for every input.
        """
        observations, mu0, goal = as_inputs(observations), as_input(mu0), as_inputs(goal)
        cfg = self.config
        u = self._initial_belief(mu0)                                      # (B, K, Dz)
        b, k, dz = u.shape
        sensors = self._resolve(observations, u[:, 0], goal)
        if cfg.method != "flow":
            return self._descend(sensors, u[:, 0])
        dmat = shift_matrix(cfg.order, dz)                                 # (K·Dz, K·Dz)
        need_h = cfg.integrator != "euler"
        steps = torch.zeros(b, dtype=torch.long)
        converged = torch.zeros(b, dtype=torch.bool)
        diverged = torch.zeros(b, dtype=torch.bool)
        diverged_step = torch.full((b,), -1, dtype=torch.long)
        free = torch.full((b,), float("nan"), dtype=torch.float64)
        start_error = torch.zeros(b, dtype=torch.float64)                  # E at the first step, per trial
        active = torch.arange(b)
        trajectory = {"mu": [], "F": []} if cfg.record else None
        evaluations = 0
        descent = cfg.descends
        dt = torch.full((b,), cfg.dt, dtype=torch.float64)                 # per trial: shrinks on rejected steps
        cand = u.clone()                                                   # the point each trial evaluates next
        cache = _Cache(b, k * dz, need_h) if descent else None
        for t in range(cfg.max_steps):
            if active.numel() == 0:
                break
            ua = cand[active]                                              # (b_a, K, Dz)
            f_a, grad, hess, errors = self._terms(sensors, ua, active, need_h)
            evaluations += active.numel()
            if descent and t > 0:                                          # accept where F did not rise
                ok = torch.isfinite(f_a) & (f_a <= free[active] + DESCENT_SLACK * free[active].abs())
                moved = (ua - u[active]).abs().amax(dim=(1, 2))
                u[active[ok]] = ua[ok]
                dt[active] = torch.where(ok, (dt[active] * DT_GROW).clamp(max=cfg.dt), dt[active] * DT_SHRINK)
                f_a, grad, hess, errors = cache.merge(active, ok, f_a, grad, hess, errors)
                done = moved < cfg.tol                                     # rejected too: no descent left
                                                                           # within tol of this belief
                converged[active[done]] = True
                keep = ~done
                active, f_a, grad = active[keep], f_a[keep], grad[keep]
                hess = hess[keep] if hess is not None else None
                errors = {name: e[keep] for name, e in errors.items()}
                if active.numel() == 0:
                    break
                ua = u[active]
            if descent:
                cache.store(active, f_a, grad, hess, errors)
            energy = sum(errors.values(), torch.zeros_like(f_a))           # (b_a,) E = Σ ½ εᵀΠε
            if t == 0:
                start_error[active] = energy
            flow = shift(ua) - cfg.k_z * grad                              # (b_a, K, Dz) u̇ = Dμ̃ − k ∂F/∂μ̃
            if need_h:
                hess = 0.5 * (hess + hess.transpose(1, 2))                 # exactly symmetric (eigh fast path)
                jac_flow = dmat[None] - cfg.k_z * hess                     # (b_a, K·Dz, K·Dz) 𝓙
                du = STEPS[cfg.integrator](flow.reshape(-1, k * dz), jac_flow, dt[active]).reshape(ua.shape)
            else:
                du = dt[active, None, None] * flow
            raw = du.abs().amax(dim=(1, 2))                                # (b_a,)
            # Divergence. Only for Euler is a huge step the instability itself; a Newton-like step near a singular
            # pose is legitimate and is cut by the trust region below. Under descent control a step too large is
            # undone when evaluated, never taken.
            bad = ~torch.isfinite(f_a) | ~torch.isfinite(raw)
            if not need_h and not descent:
                bad |= raw > cfg.divergence_step
            if cfg.divergence_ratio is not None and not descent:
                bad |= energy > cfg.divergence_ratio * start_error[active].clamp_min(1.0)
            if cfg.max_step is not None:
                scale = (cfg.max_step / du[:, 0].abs().amax(-1).clamp_min(1e-300)).clamp(max=1.0)
                du = du * torch.where(bad, 0.0, scale)[:, None, None]
            new = ua + du
            new[:, 0] = torch.minimum(torch.maximum(new[:, 0], self.low), self.high)
            moved = (new - ua).abs().amax(dim=(1, 2))                      # (b_a,)
            if descent:                                                    # a step whose predicted gain is below
                step = (new - ua).reshape(len(ua), -1)                     # F's float noise cannot be verified:
                gain = -(grad.reshape(len(ua), -1) * step).sum(-1)         # converged (−gᵀΔ − ½ ΔᵀHΔ)
                if hess is not None:
                    gain = gain - 0.5 * torch.einsum("bi,bij,bj->b", step, hess, step)
                moved = torch.where(gain <= DESCENT_SLACK * f_a.abs(), torch.zeros_like(moved), moved)
            if trajectory is not None:
                record_step(trajectory, b, active, ua, f_a, errors)
            free[active] = torch.where(torch.isfinite(f_a), f_a, free[active])
            cand[active[~bad]] = new[~bad]
            if not descent:
                u[active[~bad]] = new[~bad]
            steps[active] = t + 1
            diverged[active[bad]] = True
            diverged_step[active[bad]] = t
            done = ~bad & (moved < cfg.tol)                                # descent: judged when evaluated
            converged[active[done]] = True
            active = active[~bad & ~done]
        keep = torch.nonzero(~diverged).squeeze(-1)
        if keep.numel() and not descent:                                   # descent: F at u is already known
            free[keep] = self._terms(sensors, u[keep], keep, False, need_grad=False)[0]
            evaluations += keep.numel()
        traj = None
        if trajectory is not None:
            traj = {name: torch.stack(rows) if rows else torch.empty(0, b) for name, rows in trajectory.items()}
        return PerceptionResult(u[:, 0].clone(), u, steps, converged, diverged, diverged_step, free,
                                evaluations, traj)

    # ---- internals --------------------------------------------------------------------------------------
    def _descend(self, sensors: _Sensors, mu0: torch.Tensor) -> PerceptionResult:
        """Order 0 by Levenberg–Marquardt or Adam (descent.py) on the same F, gradient and curvature."""
        cfg = self.config

        def objective(rows, mu, need_grad, need_hess):
            free, grad, hess, errors = self._terms(sensors, mu[:, None], rows, need_hess, need_grad=need_grad)
            return descent.Terms(free, grad[:, 0] if need_grad else None, hess, errors)

        common = dict(max_steps=cfg.max_steps, tol=cfg.tol, max_step=cfg.max_step, record=cfg.record)
        if cfg.method == "lm":
            r = descent.levenberg_marquardt(objective, mu0, self.low, self.high, damping=cfg.damping, **common)
        elif cfg.method == "adam":
            r = descent.adam(objective, mu0, self.low, self.high, lr=cfg.lr, patience=cfg.patience, **common)
        else:
            r = descent.adam_then_lm(objective, mu0, self.low, self.high, lr=cfg.lr, patience=cfg.patience,
                                     handover=cfg.handover, **common)
        traj = None if r.trajectory is None else \
            {name: torch.stack(rows) if rows else torch.empty(0, len(mu0)) for name, rows in r.trajectory.items()}
        diverged_step = torch.where(r.diverged, 0, -1)
        return PerceptionResult(r.mu.clone(), r.mu[:, None].clone(), r.steps, r.converged, r.diverged, diverged_step,
                                r.free, r.evaluations, traj)

    def _initial_belief(self, mu0) -> torch.Tensor:
        k, dz = self.config.order + 1, self.latent_dim
        if not isinstance(mu0, torch.Tensor) or mu0.ndim not in (2, 3) or mu0.shape[-1] != dz \
                or (mu0.ndim == 3 and mu0.shape[1] != k):
            got = tuple(mu0.shape) if isinstance(mu0, torch.Tensor) else type(mu0).__name__
            raise ValueError(must_be("mu0", f"a tensor of shape (B, {dz}) or (B, {k}, {dz}) in rad", got))
        if not torch.isfinite(mu0).all():
            raise ValueError(must_be("mu0", "finite", "NaN or inf values"))
        u = torch.zeros(mu0.shape[0], k, dz, dtype=torch.float64)
        if mu0.ndim == 2:
            u[:, 0] = mu0.to(torch.float64)
        else:
            u[:] = mu0.to(torch.float64)
        u[:, 0] = torch.minimum(torch.maximum(u[:, 0], self.low), self.high)
        return u

    def _resolve(self, observations, mu0: torch.Tensor, goal) -> _Sensors:
        b = mu0.shape[0]
        fixed, broken = {}, set()
        for m in self.models:
            out = (b, *m.output_shape)
            if m.modality in self.precisions:
                pi = torch.as_tensor(self.precisions[m.modality], dtype=torch.float64)
                try:
                    fixed[m.modality] = pi.expand(out).clone()
                except RuntimeError:
                    raise ValueError(must_be(f"precision of {m.modality!r}", f"a float or broadcastable to {out}",
                                             tuple(pi.shape))) from None
                if (fixed[m.modality] < 0).any() or not torch.isfinite(fixed[m.modality]).all():
                    raise ValueError(must_be(f"precision of {m.modality!r}", "finite and ≥ 0", "negative or inf"))
                if (fixed[m.modality] == 0).all():
                    broken.add(m.modality)
            elif self.config.precision_update == "initial":
                fixed[m.modality] = m.precision(mu0).to(torch.float64)
        check_observations(self.models, observations, b, optional=broken)
        obs = {name: x.to(torch.float64) for name, x in observations.items() if name not in broken}
        sensors = _Sensors(obs, fixed)
        if self.config.prior == "attractor":
            sensors.goal = self._check_goal(goal, b)
        elif goal is not None:
            raise ValueError(must_be("goal", "None unless config.prior is 'attractor'", sorted(goal)))
        return sensors

    def _check_goal(self, goal, b):
        if not isinstance(goal, Mapping) or len(goal) < 1:
            raise ValueError(must_be("goal", "a dict modality → (B, *out) target", goal,
                                     "The attractor prior needs a goal x_d."))
        gains = dict(self.config.goal_precisions)
        out = []
        for name, x_d in goal.items():
            model = next((m for m in self.models if m.modality == name), None)
            if model is None or not isinstance(x_d, torch.Tensor) or tuple(x_d.shape) != (b, *model.output_shape):
                raise ValueError(must_be("goal", "one of the models' modalities with a (B, *out) tensor",
                                         {name: tuple(getattr(x_d, "shape", ()))}))
            out.append((model, x_d.to(torch.float64), float(gains.get(name, self.config.attractor_gain))))
        return out

    def _terms(self, sensors: _Sensors, u: torch.Tensor, rows: torch.Tensor, need_h: bool, need_grad: bool = True):
        """F (b,), ∂F/∂μ̃ (b, K, Dz), Gauss–Newton H (b, K·Dz, K·Dz) or None, prediction errors, at beliefs u."""
        cfg = self.config
        b, k, dz = u.shape
        mu = u[:, 0]
        obs = {name: x[rows] for name, x in sensors.observations.items()}
        pis = {m.modality: sensors.fixed[m.modality][rows] if m.modality in sensors.fixed else None
               for m in self.models}
        goals, offset = _fuse_image_goal(sensors.goal, rows, mu, obs, pis, cfg.prior_precision) if k == 1 \
            else (sensors.goal, torch.zeros(b, dtype=u.dtype))
        s = sensory_terms(self.models, obs, pis, mu, need_h, need_grad=need_grad)
        free = s.free_energy + offset
        grad = torch.zeros_like(u)
        grad[:, 0] = s.grad
        hess = None
        if need_h:
            hess = torch.zeros(b, k * dz, k * dz, dtype=u.dtype)
            hess[:, :dz, :dz] = s.hessian
        f0 = a = potential = None
        prior, missing = None, False
        for model, x_d, gain in goals or ():                              # attractors add: f, A, V summed
            pull = attractor(model, mu, x_d[rows], gain, torch.ones_like(x_d[rows]))   # Π_goal = gain I
            f0 = pull.flow if f0 is None else f0 + pull.flow
            potential = pull.potential if potential is None else potential + pull.potential
            a_i = pull.jacobian if pull.jacobian is not None else torch.zeros(b, dz, dz, dtype=u.dtype)
            a = a_i if a is None else a + a_i
            missing = missing or pull.jacobian is None                     # an image goal has no A
        if missing and k > 1:
            a = None                                                       # prior_terms refuses it above order 0
        if goals or sensors.goal is None:                                  # every goal fused above: no prior left
            prior = prior_terms(u, cfg.prior, cfg.prior_precision, f0, a, potential)
        if prior is not None:
            free = free + prior.free_energy
            grad = grad + prior.grad
            if need_h:
                hess = hess + prior.hessian
        weighted = dict(s.weighted)
        if prior is not None:
            weighted["prior"] = prior.energy if prior.energy is not None else \
                0.5 * cfg.prior_precision * prior.error.pow(2).sum(dim=(1, 2))
        return free, grad, hess, weighted


def _fuse_image_goal(goals, rows, mu: torch.Tensor, obs: dict, pis: dict, prior_precision: float):
    """Order 0, an image goal whose model is also observed: the attractor's Π_z V = ½ β |x_d − g|² (β = Π_z · its
    Π_goal) and the sensory ½ |x − g|²_Π are one Gaussian term ½ |x̄ − g|²_(Π+β), x̄ = (Π x + β x_d)/(Π + β), up
    to a constant in μ. Fused, the goal costs no model call: its gradient and Gauss–Newton curvature come with the
    sensor's (priors.py: image goals never build their own Jacobian). Rewrites obs/pis in place.
    → the goals left to the prior (None if there were none) and the constant (b,) to add to F."""
    offset = torch.zeros(len(rows), dtype=mu.dtype)
    if goals is None:
        return None, offset
    left = []
    for model, x_d, gain in goals:
        name = model.modality
        if x_d[0].numel() <= JACOBIAN_MAX_OUTPUTS or name not in obs or getattr(model, "precision_varies", False):
            left.append((model, x_d, gain))
            continue
        b = len(rows)
        pi = pis[name] if pis[name] is not None else model.precision(model_input(model, mu)).to(mu.dtype)  # (b, *out)
        beta = torch.as_tensor(gain * prior_precision, dtype=mu.dtype)
        x, goal = obs[name].to(mu.dtype), x_d[rows].to(mu.dtype)
        total = pi + beta
        obs[name], pis[name] = (pi * x + beta * goal) / total, total
        constant = 0.5 * (pi * beta / total * (x - goal).pow(2)).reshape(b, -1).sum(-1)
        logdet = 0.5 * (torch.log(total) - torch.where(pi > 0, pi.clamp_min(1e-300).log(), 0.0)).reshape(b, -1).sum(-1)
        offset = offset + constant + logdet                                # F_x(Π) + Π_z V = F_fused + this
    return left, offset
