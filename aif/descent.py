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
                        trial_derivatives: bool = False) -> DescentResult:
    """Batched Levenberg–Marquardt on F from mu0 (B, Dz) rad; λ₀ = `damping` (relative to diag H). A trial step is
    judged on F alone and its derivatives asked where it is accepted, or (trial_derivatives) asked with F."""
    b, dz = mu0.shape
    mu, t, steps, converged, diverged, rec, active = _start(objective, mu0, low, high, True, record)
    free, grad, hess, errors = t.free.clone(), t.grad.clone(), t.hess.clone(), dict(t.errors)
    lam = torch.full((b,), float(damping), dtype=torch.float64)
    nu = torch.full((b,), 2.0, dtype=torch.float64)
    evaluations = b
    eye = torch.eye(dz, dtype=torch.float64)
    for _ in range(max_steps):
        if active.numel() == 0:
            break
        rec.add(active, mu[active], free[active], {k: v[active] for k, v in errors.items()})
        g, h, m = grad[active], hess[active], mu[active]
        diag = torch.diagonal(h, dim1=1, dim2=2)                                  # (b, Dz)
        scale = diag + 1e-9 * diag.amax(-1, keepdim=True) + 1e-300                # unobservable joint: still damped
        system = h + lam[active, None, None] * torch.diag_embed(scale) + 1e-12 * eye * scale.amax(-1)[:, None, None]
        step = _bound(torch.linalg.solve(system, -g.unsqueeze(-1)).squeeze(-1), max_step)   # (b, Dz)
        new = _clamp(m + step, low, high)
        step = new - m
        gain = -(g * step).sum(-1) - 0.5 * torch.einsum("bi,bij,bj->b", step, h, step)     # predicted decrease
        trial = objective(active, new, trial_derivatives, trial_derivatives)     # F alone, or with derivatives
        evaluations += active.numel()
        rho = (free[active] - trial.free) / gain.clamp_min(1e-300)
        ok = torch.isfinite(trial.free) & (trial.free < free[active]) & (gain > 0)
        steps[active] += 1
        if ok.any():                                                              # gradient and H where accepted
            acc = active[ok]
            full = _rows(trial, ok) if trial_derivatives else objective(acc, new[ok], True, True)
            mu[acc], free[acc], grad[acc], hess[acc] = new[ok], full.free, full.grad, full.hess
            for k, v in full.errors.items():
                errors[k][acc] = v
            r = rho[ok]
            lam[acc] = lam[acc] * torch.clamp(1 - (2 * r - 1) ** 3, min=1 / 3)
            nu[acc] = 2.0
        lam[active[~ok]] = lam[active[~ok]] * nu[active[~ok]]
        nu[active[~ok]] = nu[active[~ok]] * 2
        moved = step.abs().amax(-1)
        energy = sum(e[active] for e in errors.values())                       # E = Σ ½εᵀΠε: F without ln|Π|
        done = (moved < tol) | (gain <= F_NOISE * energy) | (lam[active] > LM_LAMBDA_MAX)
        converged[active[done]] = True
        active = active[~done]
    return DescentResult(mu, free, steps, converged, diverged, evaluations, rec.rows)


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


def _rows(terms: Terms, ok: torch.Tensor) -> Terms:
    """The rows ok of a trial's terms (F, gradient, H, prediction errors)."""
    return Terms(terms.free[ok], terms.grad[ok], terms.hess[ok], {k: v[ok] for k, v in terms.errors.items()})


def adam_then_lm(objective: Objective, mu0: torch.Tensor, low, high, *, max_steps: int, tol: float, lr: float,
                 patience: int, handover: float, max_step: float | None, record: bool,
                 trial_derivatives: bool = False, check_every: int = 1) -> DescentResult:
    """Adam until its step is below `handover` rad, then Levenberg–Marquardt (λ₀ = 0.1) from its best belief."""
    first = adam(objective, mu0, low, high, max_steps=max_steps, tol=handover, lr=lr, patience=patience,
                 max_step=max_step, record=record, check_every=check_every)
    second = levenberg_marquardt(objective, first.mu, low, high, max_steps=max_steps, tol=tol, damping=0.1,
                                 max_step=max_step, record=record, trial_derivatives=trial_derivatives)
    trajectory = None
    if record:                                                             # one time axis: Adam's rows, then LM's
        trajectory = {name: first.trajectory.get(name, []) + second.trajectory.get(name, [])
                      for name in {*first.trajectory, *second.trajectory}}
    return DescentResult(second.mu, second.free, first.steps + second.steps, second.converged,
                         first.diverged | second.diverged, first.evaluations + second.evaluations, trajectory)
