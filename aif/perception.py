"""Perception: a batch of beliefs μ̃ over the joints descends the Laplace free energy of any set of SensoryModels.

    F = Σ_m ½ ε_mᵀ Π_m ε_m + ½ ε_zᵀ Π_z ε_z − ½ ln|Π|      (free_energy.py, priors.py)

`Perception.infer` checks the inputs, resolves the sensors once (precisions, broken sensors, goals:
attractor_goals.py) and runs the update of its config, "auto" resolved from its models (perception_config.py):
generalized filtering (flow.py, any order) or, at order 0, Levenberg–Marquardt or Adam (descent.py), all on the same
F, gradient and Gauss–Newton curvature (`_terms`). Every trial stops on its own, converged or diverged. Batched and
per-trial runs perform the same arithmetic row by row (bit-equal for float64 models; a float32 network may round
differently at another batch size).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from bodyschema.aif import descent
from bodyschema.aif.attractor_goals import checked_goals, fuse_image_goals
from bodyschema.aif.flow import FlowRun
from bodyschema.aif.free_energy import check_models, check_observations, sensory_terms
from bodyschema.aif.perception_config import DEFAULTS, PerceptionConfig, resolve
from bodyschema.aif.precisions import perceived_precisions
from bodyschema.aif.priors import attractor, prior_terms
from bodyschema.errors import must_be
from bodyschema.models.contract import as_input


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
    trajectory: dict[str, torch.Tensor] | None = None  # "mu" (T, B, K, Dz), "F" (T, B), "error:<m>" (T, B);
                                                       # NaN once a trial stopped

    @property
    def n_diverged(self) -> int:
        return int(self.diverged.sum())


def as_inputs(named):
    """{name: numpy array or tensor} → {name: tensor}; anything else is left for the checks to judge."""
    return {k: as_input(v) for k, v in named.items()} if isinstance(named, Mapping) else named


@dataclass
class _Sensors:                    # what one run needs about its observations, resolved once
    observations: dict[str, torch.Tensor]
    fixed: dict[str, torch.Tensor]            # modality → (B, *out) precision held fixed
    goal: list[tuple[object, torch.Tensor, float]] | None = None   # (model, x_d (B, *out), Π_goal) per modality


class Perception:
    """Batched perception over any set of SensoryModels of the same body.

    models: one model per modality, all over the same robot and joints (checked).
    config: what to run; its "auto" method and step control are resolved for these models (`self.config`).
    precisions: modality → float or tensor (broadcast to (B, *out)) overriding `model.precision`; 0 = broken
        sensor, its observation may then be omitted. Overrides here win over `config.precisions`; a modality named
        in neither follows the precision rule (aif/precisions.py: a pose-varying Π → the sensor's). `self.precisions`
        holds what was resolved.
    limits: (low, high) rad per joint; defaults to the models' `body.q_low / q_high`.
    """

    def __init__(self, models: Sequence, config: PerceptionConfig = DEFAULTS,
                 precisions: Mapping[str, float | torch.Tensor] | None = None,
                 limits: tuple[Sequence[float], Sequence[float]] | None = None):
        self.models = list(models)
        self.body = check_models(self.models)
        known = {m.modality for m in self.models}
        self.config = resolve(config, known)                               # "auto" → the update for these models
        self._overrides = dict(precisions or {})
        given = {**dict(config.precisions), **self._overrides}
        for name in given:
            if name not in known:
                raise ValueError(must_be("precision override key", f"one of the models' modalities {sorted(known)}",
                                         name))
        self.precisions = perceived_precisions(self.models, given)         # the one rule (aif/precisions.py)
        low, high = limits if limits is not None else (self.body.q_low, self.body.q_high)
        self.low = torch.as_tensor(low, dtype=torch.float64)
        self.high = torch.as_tensor(high, dtype=torch.float64)
        if self.low.shape != (self.body.latent_dim,) or self.high.shape != self.low.shape:
            raise ValueError(must_be("limits", f"two sequences of {self.body.latent_dim} angles in rad",
                                     (tuple(self.low.shape), tuple(self.high.shape))))

    @property
    def latent_dim(self) -> int:
        return self.body.latent_dim

    def with_config(self, config: PerceptionConfig) -> Perception:
        """The same models, precision overrides and limits under another config, e.g. a `dataclasses.replace` of
        `self.config` (multi-start screens its starts with fewer steps)."""
        return Perception(self.models, config, self._overrides, (self.low, self.high))

    # ---- public -----------------------------------------------------------------------------------------
    def infer(self, observations: Mapping[str, torch.Tensor], mu0: torch.Tensor,
              goal: Mapping[str, torch.Tensor] | None = None) -> PerceptionResult:
        """Run inference for B trials. observations: modality → (B, *out); mu0: (B, Dz) or (B, K, Dz) rad.

        goal: for prior "attractor", modality → (B, *out) target x_d in that model's output space (one or more:
            their attractors add up, each with Π_goal from config.goal_precisions, else attractor_gain).
        Inference is deterministic: no generator is needed. numpy arrays are accepted for every input.
        """
        observations, mu0, goal = as_inputs(observations), as_input(mu0), as_inputs(goal)
        u = self._initial_belief(mu0)                                      # (B, K, Dz)
        sensors = self._resolve(observations, u[:, 0], goal)
        if self.config.method != "flow":
            return self._descend(sensors, u[:, 0])
        return self._flow(sensors, u)

    def free_energy(self, observations: Mapping[str, torch.Tensor], mu: torch.Tensor) -> torch.Tensor:
        """F (B,) at beliefs mu (B, Dz) or (B, K, Dz) rad, nothing updated: the F every update descends, with this
        perception's precisions and prior (e.g. at the true poses, to calibrate a tracker's lost-track threshold)."""
        return self.energies(observations, mu)[0]

    def energies(self, observations: Mapping[str, torch.Tensor], mu: torch.Tensor
                 ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """F (B,) and each term's precision-weighted prediction error ½ εᵀΠε (modality or "prior" → (B,)) at beliefs
        mu (B, Dz) or (B, K, Dz) rad, nothing updated (a tracker's per-sensor consistency test)."""
        observations, mu = as_inputs(observations), as_input(mu)
        u = self._initial_belief(mu)                                       # (B, K, Dz)
        sensors = self._resolve(observations, u[:, 0], None)
        with torch.no_grad():
            free, _, _, weighted = self._terms(sensors, u, torch.arange(len(u)), False, need_grad=False)
        return free, weighted

    # ---- internals --------------------------------------------------------------------------------------
    def _flow(self, sensors: _Sensors, u: torch.Tensor) -> PerceptionResult:
        """Generalized filtering from beliefs u (B, K, Dz) (flow.py): each step evaluates the active trials'
        candidates, lets descent control accept or undo them, and steps the trials still active."""
        run = FlowRun(u, self.config, self.low, self.high)
        for t in range(self.config.max_steps):
            if run.active.numel() == 0:
                break
            ua = run.cand[run.active]                                      # (b_a, K, Dz)
            # under descent control the last evaluation only judges its candidate: F alone, no derivatives
            last = run.descent and t > 0 and t == self.config.max_steps - 1
            terms = self._terms(sensors, ua, run.active, run.need_h and not last, need_grad=not last)
            run.evaluations += run.active.numel()
            if run.descent and t > 0:
                ua, terms = run.accept(ua, terms)
                if run.active.numel() == 0:
                    break
            if last:
                run.finish(t, ua, terms)
                break
            run.step(t, ua, terms)
        keep = torch.nonzero(~run.diverged).squeeze(-1)
        if keep.numel() and not run.descent:                               # descent: F at u is already known
            run.free[keep] = self._terms(sensors, run.u[keep], keep, False, need_grad=False)[0]
            run.evaluations += keep.numel()
        return PerceptionResult(run.u[:, 0].clone(), run.u, run.steps, run.converged, run.diverged,
                                run.diverged_step, run.free, run.evaluations, run.trajectory_tensors())

    def _descend(self, sensors: _Sensors, mu0: torch.Tensor) -> PerceptionResult:
        """Order 0 by Levenberg–Marquardt or Adam (descent.py) on the same F, gradient and curvature."""
        cfg = self.config

        def objective(rows, mu, need_grad, need_hess):
            free, grad, hess, errors = self._terms(sensors, mu[:, None], rows, need_hess, need_grad=need_grad)
            return descent.Terms(free, grad[:, 0] if need_grad else None, hess, errors)

        common = dict(max_steps=cfg.max_steps, tol=cfg.tol, max_step=cfg.max_step, record=cfg.record)
        if cfg.method == "lm":
            r = descent.levenberg_marquardt(objective, mu0, self.low, self.high, damping=cfg.lm.damping,
                                            trial_derivatives=cfg.lm.trial_derivatives,
                                            check_every=cfg.check_every, **common)
        elif cfg.method == "adam":
            r = descent.adam(objective, mu0, self.low, self.high, lr=cfg.adam.lr, patience=cfg.adam.patience,
                             check_every=cfg.check_every, **common)
        else:
            r = descent.adam_then_lm(objective, mu0, self.low, self.high, lr=cfg.adam.lr,
                                     patience=cfg.adam.patience, handover=cfg.adam.handover,
                                     check_every=cfg.check_every,
                                     trial_derivatives=cfg.lm.trial_derivatives, **common)
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
            sensors.goal = checked_goals(self.models, goal, b, self.config)
        elif goal is not None:
            raise ValueError(must_be("goal", "None unless config.prior is 'attractor'", sorted(goal)))
        return sensors

    def _terms(self, sensors: _Sensors, u: torch.Tensor, rows: torch.Tensor, need_h: bool, need_grad: bool = True):
        """F (b,), ∂F/∂μ̃ (b, K, Dz), Gauss–Newton H (b, K·Dz, K·Dz) or None, prediction errors, at beliefs u."""
        cfg = self.config
        b, k, dz = u.shape
        mu = u[:, 0]
        obs = {name: x[rows] for name, x in sensors.observations.items()}
        pis = {m.modality: sensors.fixed[m.modality][rows] if m.modality in sensors.fixed else None
               for m in self.models}
        goals, offset = fuse_image_goals(sensors.goal, rows, mu, obs, pis, cfg.prior_precision) if k == 1 \
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
