"""Hyper-parameter search of `gpr`: maximize the exact marginal likelihood (MLL) of O independent GPs.

Each output o has θ_o = (log ℓ (D), log s, log σ²) (inputs in [-1, 1], standardized targets). The MLL and its
gradient are closed form (`_gp_math.neg_mll_and_grad`: one Cholesky and one inverse per evaluation, ~4× cheaper
than autograd through the Cholesky as gpytorch does). The outputs' likelihoods are independent, so:
1. a coarse L-BFGS-B run per output on COARSE_POINTS of the hyper subset: its exploratory steps (line searches
   that overshoot, curvature still unknown) cost ~1/10 of an evaluation on 500 points (1.1 vs 11 ms, 1 thread);
2. optional Adam steps on the hyper subset (elementwise, so all outputs at once are O separate Adams);
3. L-BFGS-B per output on the whole hyper subset from there, each stopping at its own convergence.

Measured on nao_arm, 2000 poses, hyper subset 500, 1 thread (noise-free / 1 mm noise): the former gpytorch loop
(50 Adam steps + ~185 joint L-BFGS evaluations, autograd) made the whole fit take ~10 s / ~20 s of CPU; this
search with fine runs only takes 0.62 s / 0.42 s (75 / 48 evaluations), coarse then fine 0.26 s / 0.27 s (~60
evaluations on 150 points, ~6 per output on 500), for the same held-out error (0.7 µm / 0.251 mm); conditioning
on the 2000 poses adds 0.28 s.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.optimize
import torch
from tqdm.auto import tqdm

from bodyschema.models import _gp_data, _gp_math

START = (0.5, 1.0, 1e-3)          # ℓ, s, σ² where every search begins (ℓ = 2 made panda's fit stall: 622 mm)
LENGTHSCALE_RANGE = (1e-3, 1e5)   # 1e5 switches an input off (nao_arm's y does not depend on its first joint)
OUTPUTSCALE_RANGE = (1e-6, 1e6)   # noise-free kinematics fits s ≈ 80
NOISE_MAX = 10.0                  # a noise variance above the target variance leaves nothing to fit
COARSE_POINTS = 150               # the coarse run's subset; skipped when the hyper subset is under twice that
# L-BFGS-B stops when a step gains less than this fraction of |−MLL| (~0.01 nats on 500 points of nao_arm): below
# the hyper-parameters' statistical resolution; scipy's default (2.2e-9) spent ~40 % more evaluations on the tail.
COARSE_FTOL, FINE_FTOL = 1e-4, 1e-5
# L-BFGS-B's first step is 1 along −∇/|∇| in the variables it is given, a factor e on every hyper-parameter from
# θ: it overshot by up to 10 orders of magnitude in −MLL and back-tracked. It is given θ / STEP_SCALE instead.
STEP_SCALE = 0.1
# A fit whose −MLL per point is within PLATEAU_NATS of the targets read as independent Gaussian noise (`iid_neg_mll`)
# sits on the plateau of tiny lengthscales (K ≈ s·I, gradient ≈ 0), where the coarse run stranded SO-101's y output
# (ℓ = 0.002 on every joint, 1.39 nats vs 1.38 for noise: 142 mm held-out error instead of 6 mm); it is searched
# again from START. A fit that found structure is far below (−1.1 and −2.1 nats on the same arm's x and z).
PLATEAU_NATS = 0.1

EpochCallback = Callable[[int, dict[str, float]], None]
# −MLL and its gradient in θ of O GPs on inputs (m, D) and targets (O, m), given (ℓ or the kernel's per-input
# parameter (O, D), s (O,), σ² (O,)): `_gp_math.neg_mll_and_grad` (RBF) or `_gp_trig.neg_mll_and_grad` (kinematic)
Objective = Callable[..., tuple[torch.Tensor, torch.Tensor]]


def log_bounds(latent_dim: int, noise_floor: float) -> np.ndarray:
    """Bounds of θ = (log ℓ (D), log s, log σ²). → (D+2, 2) [low, high]."""
    rows = [LENGTHSCALE_RANGE] * latent_dim + [OUTPUTSCALE_RANGE, (noise_floor, max(NOISE_MAX, noise_floor))]
    return np.log(np.asarray(rows, dtype=np.float64))


def initial_log_params(n_out: int, bounds: np.ndarray) -> torch.Tensor:
    """θ at START for each output, clipped into the bounds (a noise floor above 1e-3 starts at the floor). # (O, D+2)"""
    lengthscale, outputscale, noise = START
    start = np.log([lengthscale] * (bounds.shape[0] - 2) + [outputscale, noise]).clip(bounds[:, 0], bounds[:, 1])
    return torch.from_numpy(start).expand(n_out, -1).clone()


def split_log_params(theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """θ (O, D+2) → lengthscale (O, D), outputscale (O,), noise (O,)."""
    return theta[:, :-2].exp(), theta[:, -2].exp(), theta[:, -1].exp()


class MarginalLikelihood:
    """−MLL of the O outputs on (u (m, D), ys (O, m)) or a subset of the points, counting and reporting every
    evaluation: on_epoch(step, {"train_neg_mll": Σ_o −MLL_o / m_o}), each output at its latest evaluation."""

    def __init__(self, u: torch.Tensor, ys: torch.Tensor, on_epoch: EpochCallback | None, progress: bool,
                 objective: Objective = _gp_math.neg_mll_and_grad):
        self.u, self.ys, self.on_epoch, self.objective = u, ys, on_epoch, objective
        self.latest = torch.zeros(ys.shape[0], dtype=torch.float64)          # (O,) −MLL per point
        self.steps = 0
        self.bar = tqdm(total=None, desc="gpr hyper-parameters", disable=not progress)

    def __call__(self, theta: torch.Tensor, outputs: list[int], points: torch.Tensor | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor]:
        """θ (k, D+2) of `outputs` (k of them) on `points` (indices; None: all). → −MLL (k,), ∂/∂θ (k, D+2)."""
        u, ys = (self.u, self.ys[outputs]) if points is None else (self.u[points], self.ys[outputs][:, points])
        loss, grad = self.objective(u, ys, *split_log_params(theta))  # (k,), (k, D+2)
        self.record(outputs, loss / u.shape[0])
        return loss, grad

    def record(self, outputs: list[int], loss_per_point: torch.Tensor) -> None:
        self.latest[outputs] = loss_per_point
        self.steps += 1
        self.bar.update(1)
        if self.on_epoch is not None:
            self.on_epoch(self.steps, {"train_neg_mll": float(self.latest.sum())})


def fit_log_params(u: torch.Tensor, ys: torch.Tensor, gen: torch.Generator, *, noise_floor: float, adam_steps: int,
                   lr: float, lbfgs_steps: int, on_epoch: EpochCallback | None = None, progress: bool = False,
                   objective: Objective = _gp_math.neg_mll_and_grad) -> tuple[torch.Tensor, float, int]:
    """θ (O, D+2) at the MLL optimum of (u (m, D), ys (O, m)), its −MLL summed over the outputs, and the number of
    MLL evaluations.

    gen draws the coarse subset. lbfgs_steps caps the evaluations of each L-BFGS-B run (0: none, Adam only).
    objective: the kernel's −MLL and gradient (the RBF's by default).
    """
    n_out, m = ys.shape
    bounds = log_bounds(u.shape[1], noise_floor)                                   # (D+2, 2)
    theta = initial_log_params(n_out, bounds)                                      # (O, D+2)
    mll = MarginalLikelihood(u, ys, on_epoch, progress, objective)
    coarse = _gp_data.random_subset(m, COARSE_POINTS, gen) if m >= 2 * COARSE_POINTS else None
    mll(theta, list(range(n_out)), coarse)                                         # the start, every output
    if lbfgs_steps > 0 and coarse is not None:
        for o in range(n_out):
            theta[o], _ = lbfgs(lambda row, o=o: mll(row[None], [o], coarse), theta[o], bounds, lbfgs_steps,
                                COARSE_FTOL)
    if adam_steps > 0:
        theta = adam(lambda params: mll(params, list(range(n_out)))[1], theta, bounds, adam_steps, lr)
    for o in range(n_out if lbfgs_steps > 0 else 0):
        theta[o], loss = lbfgs(lambda row, o=o: mll(row[None], [o]), theta[o], bounds, lbfgs_steps, FINE_FTOL)
        if loss / m > iid_neg_mll(ys[o]) - PLATEAU_NATS:
            theta[o], loss = restart_if_better(lambda row, o=o: mll(row[None], [o]), theta[o], loss, bounds,
                                               lbfgs_steps)
        mll.latest[o] = loss / m                # the optimum (the last evaluation may be a rejected trial step)
    mll.bar.close()
    return theta, float(mll.latest.sum()) * m, mll.steps


def iid_neg_mll(y: torch.Tensor) -> float:
    """−MLL per point of targets y (m,) as independent N(0, v) at the best v = mean(y²): ½ ln(2π v) + ½
    (−inf for all-zero targets, e.g. a planar arm's z: no plateau to escape)."""
    variance = float(y.pow(2).mean())
    return 0.5 * (float(np.log(2 * np.pi * variance)) + 1.0) if variance > 0 else float("-inf")


def restart_if_better(evaluate: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]], theta: torch.Tensor,
                      loss: float, bounds: np.ndarray, lbfgs_steps: int) -> tuple[torch.Tensor, float]:
    """One output's fit searched again by L-BFGS-B from START (θ (D+2,), its −MLL `loss`): the better of the two."""
    again, again_loss = lbfgs(evaluate, initial_log_params(1, bounds)[0], bounds, lbfgs_steps, FINE_FTOL)
    return (again, again_loss) if again_loss < loss else (theta, loss)


def adam(gradient: Callable[[torch.Tensor], torch.Tensor], theta: torch.Tensor, bounds: np.ndarray, steps: int,
         lr: float) -> torch.Tensor:
    """`steps` Adam steps on θ (O, D+2) within the bounds; gradient(θ) → ∂(−MLL)/∂θ (O, D+2)."""
    theta = theta.clone().requires_grad_(True)
    optimizer = torch.optim.Adam([theta], lr=lr)
    low, high = torch.from_numpy(bounds).unbind(-1)
    for _ in range(steps):
        theta.grad = gradient(theta.detach())
        optimizer.step()
        with torch.no_grad():
            theta.clamp_(low, high)
    return theta.detach()


def lbfgs(evaluate: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]], start: torch.Tensor,
          bounds: np.ndarray, max_evals: int, ftol: float) -> tuple[torch.Tensor, float]:
    """One output's θ (D+2,) at the optimum and its −MLL, by scipy's L-BFGS-B (as scikit-learn's) on θ / STEP_SCALE.
    evaluate(θ (1, D+2)) → −MLL (1,), gradient (1, D+2); at most about `max_evals` evaluations."""
    def fun(scaled: np.ndarray):
        loss, grad = evaluate(torch.from_numpy(scaled * STEP_SCALE))
        return float(loss[0]), grad[0].numpy() * STEP_SCALE

    # One BLAS thread for scipy's (D+2)-dimensional updates: 2 OpenBLAS threads made them cost more CPU time than
    # the kernel work (threads spin). The factorizations inside `evaluate` set their own count.
    with _gp_math.blas_threads(1):
        result = scipy.optimize.minimize(fun, start.numpy() / STEP_SCALE, jac=True, method="L-BFGS-B",
                                         bounds=bounds / STEP_SCALE,
                                         options={"maxfun": max_evals, "maxiter": max_evals, "ftol": ftol})
    return torch.from_numpy(result.x * STEP_SCALE), float(result.fun)
