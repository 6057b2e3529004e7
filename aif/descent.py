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

    The batch is compacted to the trials still running only every `check_every` steps (1 when recording): between
    two compactions a trial that stopped stays in the batch, masked (`on`), its state frozen exactly where it
    stopped, so the results are those of compacting every step. Every update is a masked `where` on the active rows,
    never a boolean index, so the loop reads nothing back from the tensors but at a compaction (a host
    synchronisation on a GPU)."""
    b, dz = mu0.shape
    mu, t, steps, converged, diverged, rec, active = _start(objective, mu0, low, high, False, record)
    free, grad, errors = t.free.clone(), t.grad.clone(), dict(t.errors)
    best_mu, best_free, best_grad = mu.clone(), free.clone(), grad.clone()
    best_errors = {k: v.clone() for k, v in errors.items()}
    m1, m2 = torch.zeros_like(mu), torch.zeros_like(mu)
    age = torch.zeros(b, dtype=torch.float64)            # steps since the moments were reset
    rate = torch.full((b,), float(lr), dtype=torch.float64)
    since = torch.zeros(b, dtype=torch.long)             # steps without a new best F
    evaluations = b
    b1, b2 = ADAM_BETAS
    every = 1 if record else max(1, int(check_every))
    for i in range(max_steps):
        if i % every == 0:                                                   # compaction: the one read-back
            active = active[~converged[active]]
            if active.numel() == 0:
                break
        on = ~converged[active]                                              # (b_a,) still stepping
        rec.add(active, best_mu[active], best_free[active], {k: v[active] for k, v in best_errors.items()})
        g = grad[active]
        a = age[active] + on
        age[active] = a
        m1_a = torch.where(on[:, None], b1 * m1[active] + (1 - b1) * g, m1[active])
        m2_a = torch.where(on[:, None], b2 * m2[active] + (1 - b2) * g * g, m2[active])
        m_hat, v_hat = m1_a / (1 - b1 ** a[:, None]), m2_a / (1 - b2 ** a[:, None])
        root = v_hat.sqrt()
        eps = 1e-12 * root.amax(-1, keepdim=True) + 1e-300                     # scale-free: Π may be 1e6 or 1
        rate_a = rate[active]
        step = _bound(-rate_a[:, None] * m_hat / (root + eps), max_step)
        step = torch.where(on[:, None], step, 0.0)                          # a stopped trial is evaluated in place
        mu_a, best_mu_a, best_free_a = mu[active], best_mu[active], best_free[active]
        new = _clamp(mu_a + step, low, high)
        trial = objective(active, new, True, False)
        evaluations += active.numel()
        steps[active] += on
        finite = torch.isfinite(trial.free)
        mu_a = torch.where(on[:, None], torch.where(finite[:, None], new, best_mu_a), mu_a)
        free[active] = torch.where(on, torch.where(finite, trial.free, best_free_a), free[active])
        grad_a = torch.where((on & finite)[:, None], trial.grad, g)
        energy = sum(trial.errors.values())                                  # E: the scale of F's float noise
        better = on & finite & (trial.free < best_free_a)
        gained = better & (trial.free < best_free_a - F_NOISE * energy)      # progress beyond float noise
        best_mu_a = torch.where(better[:, None], new, best_mu_a)
        best_grad_a = torch.where(better[:, None], trial.grad, best_grad[active])
        best_mu[active], best_free[active] = best_mu_a, torch.where(better, trial.free, best_free_a)
        best_grad[active] = best_grad_a
        for k, v in trial.errors.items():
            best_errors[k][active] = torch.where(better, v, best_errors[k][active])
        since_a = torch.where(on, torch.where(gained, 0, since[active] + 1), since[active])
        plateau = on & ((since_a >= patience) | ~finite)                    # halve the step, restart at best
        rate_a = torch.where(plateau, rate_a * 0.5, rate_a)
        rate[active], since[active] = rate_a, torch.where(plateau, 0, since_a)
        mu[active] = torch.where(plateau[:, None], best_mu_a, mu_a)
        grad[active] = torch.where(plateau[:, None], best_grad_a, grad_a)
        age[active] = torch.where(plateau, 0.0, a)
        m1[active] = torch.where(plateau[:, None], 0.0, m1_a)
        m2[active] = torch.where(plateau[:, None], 0.0, m2_a)
        converged[active] = converged[active] | (on & (rate_a < tol))
    return DescentResult(best_mu, best_free, steps, converged, diverged, evaluations, rec.rows)


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
