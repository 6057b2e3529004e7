"""Order-0 perception as batched minimisation of F that stays in the basin of its start: Levenberg–Marquardt and Adam.

At order 0 (no generalized motion) perception is the gradient flow dμ/dt = −k ∂F/∂μ (Friston 2010): its fixed points
are the minima of F and it never leaves the basin it starts in. On the free energy of an image decoder that basin is
small and F is far from quadratic, so a full Gauss–Newton jump (the local-linear step at a large Δt) can land in
another minimum — measured: F at the final belief above F at the true pose in 17 of 26 failed level-2 trials. Both
updates here follow the flow more closely and keep descending F monotonically (the best belief is returned):

  "lm"    Levenberg–Marquardt (Levenberg 1944; Marquardt 1963; damping update of Nielsen 1999): the step solves
          (H + λ D) Δ = −∂F/∂μ with D the diagonal of the Gauss–Newton H (scale-free per joint). λ starts large
          (a short, gradient-like step), shrinks only where the decrease of F agrees with the quadratic model's
          prediction (ratio ρ) and grows on every rejected step: the trust region starts small and grows on agreement.
  "adam"  first-order flow with per-joint adaptive steps and momentum (Kingma & Ba 2015) on −∂F/∂μ, bounded by
          max_step; on a plateau (no new best F for `patience` steps) the step halves and restarts from the best
          belief (a new best counts as progress only beyond F's float noise, so a float32 decoder's jitter does not
          keep it going). It needs only F's gradient (one VJP for an image), no Jacobian.
  "adam+lm" Adam until its step has halved to `handover` rad (it oscillates in one basin), then LM from its best
          belief: Adam crosses the rough terrain, LM then converges in a few steps where Adam would crawl along an
          ill-conditioned valley (measured on a 56×80 decoder: F still falling after 250 Adam steps from the truth).

Every trial stops on its own: lm when an accepted step moves less than tol, or its predicted gain is below F's float
noise (a float32 decoder evaluates F to ~1e-7 relative), or λ saturates; adam when its step size falls below tol.
The belief is clamped to the joint limits after every step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

DESCENT_METHODS = ("lm", "adam", "adam+lm")
F_NOISE = 1e-7                  # relative rise/gain of F not resolvable for float32 models
LM_LAMBDA_MAX = 1e10            # λ beyond this: no descent left within float noise (stalled = converged)
ADAM_BETAS = (0.9, 0.999)


@dataclass
class Terms:
    free: torch.Tensor                     # (b,)
    grad: torch.Tensor | None              # (b, Dz)
    hess: torch.Tensor | None              # (b, Dz, Dz) Gauss–Newton
    errors: dict[str, torch.Tensor]        # name → (b,) ½ εᵀΠε


# objective(rows, mu, need_grad, need_hess) → Terms at beliefs mu (b, Dz) of the trials `rows`
Objective = Callable[[torch.Tensor, torch.Tensor, bool, bool], Terms]


@dataclass
class DescentResult:
    mu: torch.Tensor            # (B, Dz) best belief
    free: torch.Tensor          # (B,) F at mu
    steps: torch.Tensor         # (B,) long, updates performed
    converged: torch.Tensor     # (B,) bool
    diverged: torch.Tensor      # (B,) bool: F never finite from the start
    evaluations: int            # model-evaluation rounds × trials
    trajectory: dict[str, list[torch.Tensor]] | None


def record_step(trajectory: dict, b: int, active, u, free, errors) -> None:
    """Append one step's rows to a trajectory: beliefs u (b_a, K, Dz), F and prediction errors of the active trials,
    NaN for the trials that stopped. Shared with the generalized-filtering loop (perception.py)."""
    mu = torch.full((b, *u.shape[1:]), float("nan"), dtype=u.dtype)
    mu[active] = u
    trajectory["mu"].append(mu)
    for name, values in (("F", free), *((f"error:{m}", e) for m, e in errors.items())):
        row = torch.full((b,), float("nan"), dtype=free.dtype)
        row[active] = values
        trajectory.setdefault(name, []).append(row)


class _Recorder:
    """Per-step rows of the trajectory (record_step), or nothing when recording is off."""

    def __init__(self, b: int, on: bool):
        self.b, self.rows = b, ({"mu": [], "F": []} if on else None)

    def add(self, active, mu, free, errors):
        if self.rows is not None:
            record_step(self.rows, self.b, active, mu[:, None], free, errors)


def _clamp(mu, low, high):
    return torch.minimum(torch.maximum(mu, low), high)


def _start(objective: Objective, mu0: torch.Tensor, low, high, need_hess: bool, record: bool):
    """What both descents begin with: the clamped float64 belief, F (and derivatives) there, zeroed step and
    convergence counters, the recorder, and the active trials (those whose F is finite at the start)."""
    b = mu0.shape[0]
    mu = _clamp(mu0.to(torch.float64), low, high)
    rows = torch.arange(b)
    terms = objective(rows, mu, True, need_hess)
    diverged = ~torch.isfinite(terms.free)
    steps, converged = torch.zeros(b, dtype=torch.long), torch.zeros(b, dtype=torch.bool)
    return mu, terms, steps, converged, diverged, _Recorder(b, record), rows[~diverged]


def _bound(step: torch.Tensor, max_step: float | None) -> torch.Tensor:
    """Scale each trial's step so that no joint moves more than max_step rad. # (b, Dz)"""
    if max_step is None:
        return step
    scale = (max_step / step.abs().amax(-1, keepdim=True).clamp_min(1e-300)).clamp(max=1.0)
    return step * scale


def levenberg_marquardt(objective: Objective, mu0: torch.Tensor, low, high, *, max_steps: int, tol: float,
                        damping: float, max_step: float | None, record: bool,
                        trial_derivatives: bool = False, check_every: int = 1) -> DescentResult:
    """Batched Levenberg–Marquardt on F from mu0 (B, Dz) rad; λ₀ = `damping` (relative to diag H). A trial step is
    judged on F alone and its derivatives asked where it is accepted, or (trial_derivatives) asked with F.

    As in `adam`, the running trials' state lives in tensors of the running rows only, and whether a trial stopped
    is read back every `check_every` steps (1 when recording). Above 1 nothing in the loop reads a tensor back: every
    trial step brings its derivatives (trial_derivatives), an accepted step is taken by a mask, not gathered, and a
    stopped trial stays in the batch frozen where it stopped until the next read."""
    b, dz = mu0.shape
    mu_full, t, steps, converged, diverged, rec, active = _start(objective, mu0, low, high, True, record)
    free_full = t.free.clone()
    mu, free, grad, hess = mu_full[active], t.free[active], t.grad[active], t.hess[active]
    errors = {k: v[active] for k, v in t.errors.items()}
    lam = torch.full((len(active),), float(damping), dtype=torch.float64)
    nu = torch.full((len(active),), 2.0, dtype=torch.float64)
    taken = torch.zeros(len(active), dtype=torch.long)
    stopped = torch.zeros(len(active), dtype=torch.bool)
    evaluations = b
    eye = torch.eye(dz, dtype=torch.float64)
    every = 1 if record else max(1, int(check_every))
    held = _held if every > 1 else _all
    with_trial = trial_derivatives or every > 1
    for i in range(max_steps):
        if len(active) == 0:
            break
        rec.add(active, mu, free, errors)
        on = ~stopped
        diag = torch.diagonal(hess, dim1=1, dim2=2)                               # (b_a, Dz)
        scale = diag + 1e-9 * diag.amax(-1, keepdim=True) + 1e-300                # unobservable joint: still damped
        system = hess + lam[:, None, None] * torch.diag_embed(scale) + 1e-12 * eye * scale.amax(-1)[:, None, None]
        step = _bound(torch.linalg.solve(system, -grad.unsqueeze(-1)).squeeze(-1), max_step)   # (b_a, Dz)
        new = _clamp(mu + held(on[:, None], step, 0.0), low, high)               # a stopped trial: evaluated in place
        step = new - mu
        gain = -(grad * step).sum(-1) - 0.5 * torch.einsum("bi,bij,bj->b", step, hess, step)   # predicted decrease
        trial = objective(active, new, with_trial, with_trial)                   # F alone, or with derivatives
        evaluations += len(active)
        taken += on
        rho = (free - trial.free) / gain.clamp_min(1e-300)
        ok = held(on, torch.isfinite(trial.free) & (trial.free < free) & (gain > 0), False)
        if with_trial:
            mu, free, grad, hess, errors = _where(ok, (new, trial.free, trial.grad, trial.hess, trial.errors),
                                                  (mu, free, grad, hess, errors))
        elif bool(ok.any()):                                                      # gradient and H where accepted
            rows = ok.nonzero().squeeze(-1)
            full = objective(active[rows], new[rows], True, True)
            mu[rows], free[rows], grad[rows], hess[rows] = new[rows], full.free, full.grad, full.hess
            for k, v in full.errors.items():
                errors[k][rows] = v
        shrink = torch.clamp(1 - (2 * rho - 1) ** 3, min=1 / 3)
        lam = torch.where(ok, lam * shrink, held(on, lam * nu, lam))
        nu = torch.where(ok, 2.0, held(on, nu * 2, nu))
        moved = step.abs().amax(-1)
        energy = sum(errors.values())                                            # E = Σ ½εᵀΠε: F without ln|Π|
        done = (moved < tol) | (gain <= F_NOISE * energy) | (lam > LM_LAMBDA_MAX)
        stopped = stopped | held(on, done, False)
        if (i + 1) % every == 0 and bool(stopped.any()):                         # the one read-back: compact
            out, keep = stopped.nonzero().squeeze(-1), (~stopped).nonzero().squeeze(-1)
            rows = active[out]
            mu_full[rows], free_full[rows], steps[rows], converged[rows] = mu[out], free[out], taken[out], True
            active, mu, free, grad, hess, lam, nu, taken, stopped = (
                x[keep] for x in (active, mu, free, grad, hess, lam, nu, taken, stopped))
            errors = {k: v[keep] for k, v in errors.items()}
    converged[active] = stopped                                                  # the rows left at the last step
    mu_full[active], free_full[active], steps[active] = mu, free, taken
    return DescentResult(mu_full, free_full, steps, converged, diverged, evaluations, rec.rows)


def adam(objective: Objective, mu0: torch.Tensor, low, high, *, max_steps: int, tol: float, lr: float,
         patience: int, max_step: float | None, record: bool, check_every: int = 1) -> DescentResult:
    """Batched Adam on F from mu0 (B, Dz) rad: step lr rad per joint, halved on a plateau of `patience` steps.

    The running trials' state lives in tensors of the running rows only (no gather/scatter of (B, …) tensors per
    step); the batch is compacted when a trial stops. Whether one did is read back (a host synchronisation on a GPU)
    every `check_every` steps (1 when recording): in between, a trial that stopped stays in the batch frozen where
    it stopped (masked), so its result is that of every step's check, but the rows still running are evaluated in a
    larger batch, which a float32 network may round differently (README, levels)."""
    b, dz = mu0.shape
    mu_full, t, steps, converged, diverged, rec, active = _start(objective, mu0, low, high, False, record)
    best_mu_full, best_free_full = mu_full.clone(), t.free.clone()
    mu, free, grad = mu_full[active], t.free[active], t.grad[active]        # (b_a, Dz), (b_a,), (b_a, Dz)
    best_mu, best_free, best_grad = mu.clone(), free.clone(), grad.clone()
    best_errors = {k: v[active] for k, v in t.errors.items()}
    m1, m2 = torch.zeros_like(mu), torch.zeros_like(mu)
    age = torch.zeros(len(active), dtype=torch.float64)  # steps since the moments were reset
    rate = torch.full((len(active),), float(lr), dtype=torch.float64)
    since = torch.zeros(len(active), dtype=torch.long)   # steps without a new best F
    taken = torch.zeros(len(active), dtype=torch.long)   # updates performed
    stopped = torch.zeros(len(active), dtype=torch.bool)
    evaluations = b
    b1, b2 = ADAM_BETAS
    every = 1 if record else max(1, int(check_every))
    held = _held if every > 1 else _all                                     # every step's check: nothing is masked
    for i in range(max_steps):
        if len(active) == 0:
            break
        rec.add(active, best_mu, best_free, best_errors)
        on = ~stopped                                                         # (b_a,) still stepping
        age = age + on
        m1 = held(on[:, None], b1 * m1 + (1 - b1) * grad, m1)
        m2 = held(on[:, None], b2 * m2 + (1 - b2) * grad * grad, m2)
        m_hat, v_hat = m1 / (1 - b1 ** age[:, None]), m2 / (1 - b2 ** age[:, None])
        root = v_hat.sqrt()
        eps = 1e-12 * root.amax(-1, keepdim=True) + 1e-300                     # scale-free: Π may be 1e6 or 1
        step = _bound(-rate[:, None] * m_hat / (root + eps), max_step)
        step = held(on[:, None], step, 0.0)                                  # a stopped trial is evaluated in place
        new = _clamp(mu + step, low, high)
        trial = objective(active, new, True, False)
        evaluations += len(active)
        taken += on
        finite = torch.isfinite(trial.free)
        live = held(on, finite, False)
        mu = held(on[:, None], torch.where(finite[:, None], new, best_mu), mu)
        free = held(on, torch.where(finite, trial.free, best_free), free)
        grad = torch.where(live[:, None], trial.grad, grad)
        energy = sum(trial.errors.values())                                  # E: the scale of F's float noise
        better = live & (trial.free < best_free)
        gained = better & (trial.free < best_free - F_NOISE * energy)        # progress beyond float noise
        best_mu = torch.where(better[:, None], new, best_mu)
        best_free = torch.where(better, trial.free, best_free)
        best_grad = torch.where(better[:, None], trial.grad, best_grad)
        best_errors = {k: torch.where(better, v, best_errors[k]) for k, v in trial.errors.items()}
        since = held(on, torch.where(gained, 0, since + 1), since)
        plateau = held(on, (since >= patience) | ~finite, False)                       # halve the step, restart at best
        rate = torch.where(plateau, rate * 0.5, rate)
        since = torch.where(plateau, 0, since)
        mu = torch.where(plateau[:, None], best_mu, mu)
        grad = torch.where(plateau[:, None], best_grad, grad)
        age = torch.where(plateau, 0.0, age)
        m1 = torch.where(plateau[:, None], 0.0, m1)
        m2 = torch.where(plateau[:, None], 0.0, m2)
        stopped = stopped | (rate < tol)
        if (i + 1) % every == 0 and bool(stopped.any()):                    # the one read-back: compact the batch
            done, keep = stopped.nonzero().squeeze(-1), (~stopped).nonzero().squeeze(-1)
            rows = active[done]
            best_mu_full[rows], best_free_full[rows], steps[rows] = best_mu[done], best_free[done], taken[done]
            converged[rows] = True
            active, mu, free, grad, best_mu, best_free, best_grad, m1, m2, age, rate, since, taken, stopped = (
                x[keep] for x in (active, mu, free, grad, best_mu, best_free, best_grad, m1, m2, age, rate, since,
                                  taken, stopped))
            best_errors = {k: v[keep] for k, v in best_errors.items()}
    converged[active] = stopped                                              # the rows left at the last step
    best_mu_full[active], best_free_full[active], steps[active] = best_mu, best_free, taken
    return DescentResult(best_mu_full, best_free_full, steps, converged, diverged, evaluations, rec.rows)


def _held(on: torch.Tensor, value, frozen):
    """value where the trial still steps, else frozen (a stopped trial waiting for the next compaction)."""
    return torch.where(on, value, frozen)


def _all(on: torch.Tensor, value, frozen):
    """value: with every step's check no stopped trial is left in the batch."""
    return value


def _where(ok: torch.Tensor, new: tuple, old: tuple) -> tuple:
    """Per row, the new values where ok, else the old ones: tensors of (b, …) rows, or dicts of (b,) rows."""
    def pick(n, o):
        if isinstance(n, dict):
            return {k: torch.where(ok, v, o[k]) for k, v in n.items()}
        return torch.where(ok.reshape(-1, *(1,) * (n.ndim - 1)), n, o)
    return tuple(pick(n, o) for n, o in zip(new, old))


def adam_then_lm(objective: Objective, mu0: torch.Tensor, low, high, *, max_steps: int, tol: float, lr: float,
                 patience: int, handover: float, max_step: float | None, record: bool,
                 trial_derivatives: bool = False, check_every: int = 1) -> DescentResult:
    """Adam until its step is below `handover` rad, then Levenberg–Marquardt (λ₀ = 0.1) from its best belief; both
    read back which trials stopped every `check_every` steps."""
    first = adam(objective, mu0, low, high, max_steps=max_steps, tol=handover, lr=lr, patience=patience,
                 max_step=max_step, record=record, check_every=check_every)
    second = levenberg_marquardt(objective, first.mu, low, high, max_steps=max_steps, tol=tol, damping=0.1,
                                 max_step=max_step, record=record, trial_derivatives=trial_derivatives,
                                 check_every=check_every)
    trajectory = None
    if record:                                                             # one time axis: Adam's rows, then LM's
        trajectory = {name: first.trajectory.get(name, []) + second.trajectory.get(name, [])
                      for name in {*first.trajectory, *second.trajectory}}
    return DescentResult(second.mu, second.free, first.steps + second.steps, second.converged,
                         first.diverged | second.diverged, first.evaluations + second.evaluations, trajectory)
