"""One run of method "flow" over B trials (perception.py evaluates F; this file steps the beliefs): per step, the
active trials' candidates are accepted or undone (descent control), then moved by the integrator.

    dμ̃/dt = Dμ̃ − k_z ∂F/∂μ̃                              (Friston et al. 2010, "Generalised filtering", eq. 5)

Integration: "local_linear" (default) takes Ozaki's step Δt φ₁(Δt 𝓙) u̇ with the Gauss–Newton flow Jacobian
𝓙 = D ⊗ I − k_z H (generalized.py): each step is precision-normalised — a damped Newton step that needs no
tuning of Δt to the sensory precision — and converges in tens of steps; "implicit" is the linearly implicit
Euler step (same limits, a solve instead of an exponential); "euler" is the plain Δt·u̇ of the Pixel-AIF
protocol. With step_control "descent" (order 0: F is then a Lyapunov function of the flow) a step that raises F
is undone and that trial's Δt shrinks ×0.1 (it regrows ×2 on accepted steps, up to dt): the Gauss–Newton
step becomes Levenberg–Marquardt-like, monotone, and a trial stops once even a step below `tol` does not
descend, instead of jittering at the float32 noise floor of a learned model; the run's last evaluation only
judges the last step, so it computes F alone (`finish`). A step of the joints is capped
at `max_step` rad (trust region), the belief is clamped to the joint limits, and every trial stops on its own:
trials that converged (moved < tol) or diverged (F or the step not finite, an Euler step > divergence_step rad, or
the precision-weighted prediction error E = F + ½ln|Π| grown above divergence_ratio · max(E at the start, 1) — an
unstable update bouncing between the joint limits) leave the active batch and are never evaluated again.
"""

from __future__ import annotations

import torch

from bodyschema.aif.descent import record_step
from bodyschema.aif.generalized import implicit_step, local_linear_step, shift, shift_matrix
from bodyschema.aif.perception_config import PerceptionConfig

STEPS = {"local_linear": local_linear_step, "implicit": implicit_step}
DESCENT_SLACK = 1e-7     # relative rise of F still accepted: float32 models evaluate F to ~1e-7
DT_GROW, DT_SHRINK = 2.0, 0.1   # Δt of a trial after an accepted / a rejected step (never above flow.dt)

# (F (b,), ∂F/∂μ̃ (b, K, Dz), Gauss–Newton H (b, K·Dz, K·Dz) or None, name → (b,) ½ εᵀΠε) at b beliefs
Terms = tuple[torch.Tensor, torch.Tensor, torch.Tensor | None, dict[str, torch.Tensor]]


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


class FlowRun:
    """The beliefs and bookkeeping of one flow run; `active` holds the trials still running.

    u: (B, K, Dz) rad, the initial beliefs (updated in place); low, high: (Dz,) rad joint limits."""

    def __init__(self, u: torch.Tensor, config: PerceptionConfig, low: torch.Tensor, high: torch.Tensor):
        b, k, dz = u.shape
        self.config, self.flow, self.low, self.high = config, config.flow, low, high
        self.need_h = config.flow.integrator != "euler"
        self.descent = config.descends
        self.dmat = shift_matrix(config.order, dz)                        # (K·Dz, K·Dz)
        self.u = u                                                         # accepted beliefs
        self.cand = u.clone()                                              # the point each trial evaluates next
        self.dt = torch.full((b,), config.flow.dt, dtype=torch.float64)    # per trial: shrinks on rejected steps
        self.steps = torch.zeros(b, dtype=torch.long)
        self.converged = torch.zeros(b, dtype=torch.bool)
        self.diverged = torch.zeros(b, dtype=torch.bool)
        self.diverged_step = torch.full((b,), -1, dtype=torch.long)
        self.free = torch.full((b,), float("nan"), dtype=torch.float64)
        self.start_error = torch.zeros(b, dtype=torch.float64)             # E at the first step, per trial
        self.active = torch.arange(b)
        self.trajectory = {"mu": [], "F": []} if config.record else None
        self.evaluations = 0
        self.cache = _Cache(b, k * dz, self.need_h) if self.descent else None

    def accept(self, ua: torch.Tensor, terms: Terms) -> tuple[torch.Tensor, Terms]:
        """Descent control, from the second step on: keep each candidate ua (b_a, K, Dz) where F did not rise, undo it
        (Δt shrinks) where it did; a trial whose candidate moved less than tol is converged, accepted or not (no
        descent left within tol of its belief). → the active trials' beliefs and terms."""
        f_a, grad, hess, errors = terms
        active, free = self.active, self.free[self.active]
        ok = torch.isfinite(f_a) & (f_a <= free + DESCENT_SLACK * free.abs())
        moved = (ua - self.u[active]).abs().amax(dim=(1, 2))
        self.u[active[ok]] = ua[ok]
        dt = self.dt[active]
        self.dt[active] = torch.where(ok, (dt * DT_GROW).clamp(max=self.flow.dt), dt * DT_SHRINK)
        f_a, grad, hess, errors = self.cache.merge(active, ok, f_a, grad, hess, errors)
        done = moved < self.config.tol
        self.converged[active[done]] = True
        keep = ~done
        self.active = active[keep]
        terms = (f_a[keep], grad[keep], hess[keep] if hess is not None else None,
                 {name: e[keep] for name, e in errors.items()})
        return self.u[self.active], terms

    def step(self, t: int, ua: torch.Tensor, terms: Terms) -> None:
        """Step t of the active trials from beliefs ua (b_a, K, Dz): the integrator's step, capped and clamped; the
        trials that diverged or converged leave the active batch."""
        f_a, grad, hess, errors = terms
        if self.descent:
            self.cache.store(self.active, f_a, grad, hess, errors)
        energy = sum(errors.values(), torch.zeros_like(f_a))               # (b_a,) E = Σ ½ εᵀΠε
        if t == 0:
            self.start_error[self.active] = energy
        if hess is not None:
            hess = 0.5 * (hess + hess.transpose(1, 2))                     # exactly symmetric (eigh fast path)
        du = self._integrate(ua, grad, hess)
        bad = self._diverging(f_a, energy, du)
        new = self._bounded(ua, du, bad)
        moved = (new - ua).abs().amax(dim=(1, 2))                          # (b_a,)
        if self.descent:
            moved = self._unverifiable_as_still(moved, new - ua, f_a, grad, hess)
        if self.trajectory is not None:
            record_step(self.trajectory, len(self.u), self.active, ua, f_a, errors)
        self._commit(t, f_a, new, moved, bad)

    def finish(self, t: int, ua: torch.Tensor, terms: Terms) -> None:
        """Book the last step t of a descent-controlled run, whose candidates were judged (`accept`) and which takes
        no step further: F at the accepted beliefs ua (b_a, K, Dz), the steps taken. A trial still active here has not
        converged: its next step, never taken, was not computed."""
        f_a, _, _, errors = terms
        if self.trajectory is not None:
            record_step(self.trajectory, len(self.u), self.active, ua, f_a, errors)
        self.free[self.active] = f_a
        self.steps[self.active] = t + 1
        self.active = self.active[:0]

    def trajectory_tensors(self) -> dict[str, torch.Tensor] | None:
        """The recorded rows stacked: "mu" (T, B, K, Dz), "F" and "error:<m>" (T, B); None when not recording."""
        if self.trajectory is None:
            return None
        b = len(self.u)
        return {name: torch.stack(rows) if rows else torch.empty(0, b) for name, rows in self.trajectory.items()}

    # ---- the parts of a step ----------------------------------------------------------------------------
    def _integrate(self, ua, grad, hess) -> torch.Tensor:
        """The integrator's step du (b_a, K, Dz) of u̇ = Dμ̃ − k ∂F/∂μ̃ (hess: None for Euler)."""
        flow = shift(ua) - self.flow.k_z * grad                            # (b_a, K, Dz)
        dt = self.dt[self.active]
        if hess is None:
            return dt[:, None, None] * flow
        jac_flow = self.dmat[None] - self.flow.k_z * hess                  # (b_a, K·Dz, K·Dz) 𝓙
        n = ua.shape[1] * ua.shape[2]
        return STEPS[self.flow.integrator](flow.reshape(-1, n), jac_flow, dt).reshape(ua.shape)

    def _diverging(self, f_a, energy, du) -> torch.Tensor:
        """(b_a,) bool. Only for Euler is a huge step the instability itself; a Newton-like step near a singular
        pose is legitimate and is cut by the trust region. Under descent control a step too large is undone when
        evaluated, never taken."""
        raw = du.abs().amax(dim=(1, 2))                                    # (b_a,)
        bad = ~torch.isfinite(f_a) | ~torch.isfinite(raw)
        if not self.need_h and not self.descent:
            bad |= raw > self.flow.divergence_step
        if self.flow.divergence_ratio is not None and not self.descent:
            bad |= energy > self.flow.divergence_ratio * self.start_error[self.active].clamp_min(1.0)
        return bad

    def _bounded(self, ua, du, bad) -> torch.Tensor:
        """ua + du with the joints' step capped at max_step (none for a diverged trial), clamped to the limits."""
        if self.config.max_step is not None:
            scale = (self.config.max_step / du[:, 0].abs().amax(-1).clamp_min(1e-300)).clamp(max=1.0)
            du = du * torch.where(bad, 0.0, scale)[:, None, None]
        new = ua + du
        new[:, 0] = torch.minimum(torch.maximum(new[:, 0], self.low), self.high)
        return new

    @staticmethod
    def _unverifiable_as_still(moved, du, f_a, grad, hess) -> torch.Tensor:
        """A step whose predicted gain −gᵀΔ − ½ ΔᵀHΔ is below F's float noise cannot be verified: converged."""
        step = du.reshape(len(du), -1)
        gain = -(grad.reshape(len(du), -1) * step).sum(-1)
        if hess is not None:
            gain = gain - 0.5 * torch.einsum("bi,bij,bj->b", step, hess, step)
        return torch.where(gain <= DESCENT_SLACK * f_a.abs(), torch.zeros_like(moved), moved)

    def _commit(self, t: int, f_a, new, moved, bad) -> None:
        """Book step t: F, the next candidates (the beliefs too without descent control), who stopped and why."""
        active = self.active
        self.free[active] = torch.where(torch.isfinite(f_a), f_a, self.free[active])
        self.cand[active[~bad]] = new[~bad]
        if not self.descent:
            self.u[active[~bad]] = new[~bad]
        self.steps[active] = t + 1
        self.diverged[active[bad]] = True
        self.diverged_step[active[bad]] = t
        done = ~bad & (moved < self.config.tol)                            # descent: judged when evaluated
        self.converged[active[done]] = True
        self.active = active[~bad & ~done]
