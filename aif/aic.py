"""The active inference controller (AIC) for torque-driven arms, batched over B episodes.

Pezzato, Ferrari & Hernández Corbato 2020, "A novel adaptive controller for robot manipulators based on active
inference" (RA-L), with extra sensory models fused as in MAIF (Meo, Franzese, Pezzato, Spahn & Lanillos 2021,
"Adaptation through prediction: multisensory active inference torque control"). Per joint the belief holds
μ̃ = (μ, μ', μ''); the sensors are q (rad) and q̇ (rad/s), plus any SensoryModel x_m = g_m(μ) over the joints.

    F = ½ Π_q |q − μ|² + ½ Π_q̇ |q̇ − μ'|² + Σ_m ½ ε_mᵀ Π_m ε_m + ½ Π_μ |μ' − f(μ)|² + ½ Π_μ' |μ'' − A μ'|²
    f(μ) = β J_gᵀ (x_d − g(μ)),  A = ∂f/∂μ ≈ −β J_gᵀ J_g      (priors.attractor_flow; joints goal: β (μ_d − μ))
    dμ̃/dt = Dμ̃ − κ_μ ∂F/∂μ̃                                  (the AIC belief update; generalized.py for D)
    du/dt = −κ_a Σ_m (∂x_m/∂u)ᵀ Π_m ε_m = −κ_a [Π_q ε_q + Π_q̇ ε_q̇ + Σ_m J_mᵀ Π_m ε_m]   (the AIC action update)
with ∂q/∂u = ∂q̇/∂u ≈ I (the AIC paper's positive-identity assumption) and ∂x_m/∂u ≈ J_m. With β = 1 (A = −I),
no extra model and the Euler step this is exactly the authors' Panda controller (AIC_controller.cpp in their
franka_custom_controllers: belief update, then the action at the updated belief, both Euler at h = 1 ms).
u integrates the weighted errors, so the AIC has the integral action that lets it absorb an unmodelled gravity
change; it is clipped to the torque limits (which also stops wind-up). The belief takes the linearly implicit
Euler step (generalized.implicit_step, Gauss–Newton flow Jacobian) by default: equal to the paper's Euler step
to O(dt²) at the default gains, and stable when an extra model's precision is large. Knows only the
SensoryModel protocol (no simulator). The reaching benchmark (evaluation/reaching.py) and the Jupiter experiment
(evaluation/jupiter.py) drive the panda through it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from bodyschema.aif.aic_config import DEFAULTS, AICConfig
from bodyschema.aif.free_energy import check_models, model_input
from bodyschema.aif.generalized import implicit_step, shift, shift_matrix
from bodyschema.aif.priors import attractor_flow
from bodyschema.errors import must_be

DIVERGED_RAD = 1e3               # a belief beyond this many rad (or non-finite) marks the episode failed


@dataclass
class _Inputs:                   # one tick's sensors for the active rows, torch float64
    q: torch.Tensor              # (b, Dq) rad
    qd: torch.Tensor             # (b, Dq) rad/s
    obs: dict[str, torch.Tensor]  # modality → (b, *out)
    goal: torch.Tensor           # (b, *out of the goal model) or (b, Dq) rad


class AICController:
    """Active inference controller (Pezzato, Ferrari & Hernández Corbato 2020; MAIF, Meo et al. 2021, for the
    multimodal form): beliefs μ, μ', μ'' per joint; sensors q, q̇ plus any extra SensoryModels over the joints
    fused with their precision; goal as an attractor f(μ) = β J_gᵀ (x_d − g(μ)) through one model (joints:
    β (μ_d − μ)); action u̇ = −k_a Σ_m (∂x_m/∂u)ᵀ Π_m ε_m, integrated and clipped to the torque limits.

    models: extra (non-proprioceptive) models, may be empty; the joints sensor is built in.
    torque_limits: (Dq,) N·m magnitudes, or (Dq, 2) [low, high] per joint.
    After `act`, `failed` (B,) marks episodes stopped by a non-finite input or a diverged belief, with `reasons`.
    """

    def __init__(self, models: Sequence, config: AICConfig = DEFAULTS, torque_limits: np.ndarray | None = None):
        self.models = list(models)
        self.config = config
        limits = np.asarray(torque_limits, dtype=np.float64) if torque_limits is not None else None
        if limits is not None and limits.ndim == 1:
            limits = np.stack([-limits, limits], axis=1)
        if limits is None or limits.ndim != 2 or limits.shape[1] != 2 or not np.isfinite(limits).all() \
                or not (limits[:, 0] < limits[:, 1]).all():
            raise ValueError(must_be("torque_limits", "a finite (Dq,) array of magnitudes > 0 or (Dq, 2) [low, high] "
                                     "in N·m", None if limits is None else limits.tolist()))
        self.dq = len(limits)
        self._low, self._high = torch.from_numpy(limits[:, 0]), torch.from_numpy(limits[:, 1])
        if self.models:
            body = check_models(self.models)
            if body.latent_dim != self.dq or any(m.modality == "joints" for m in self.models):
                raise ValueError(must_be("models", f"extra sensory models over the same {self.dq} joints as "
                                         "torque_limits (the joints sensor is built in)",
                                         [(m.modality, m.latent_dim) for m in self.models]))
        self._fixed = dict(config.precisions)
        self._live = [m for m in self.models if self._fixed.get(m.modality) != 0]   # Π = 0: a broken sensor, ignored
        self._shift = shift_matrix(2, self.dq)[None]                               # (1, 3·Dq, 3·Dq) D ⊗ I
        self._pi_prop, self._lin_prop = _proprioceptive_terms(config, self.dq)
        self._u = self._torque = None
        self.failed, self.reasons = np.zeros(0, dtype=bool), []

    # ---- public -----------------------------------------------------------------------------------------
    def reset(self, q: np.ndarray, qd: np.ndarray, goal: Mapping[str, torch.Tensor]) -> None:
        """Start B episodes: belief μ = q, μ' = q̇, μ'' = 0, torque 0. q (B, Dq) rad, qd (B, Dq) rad/s;
        goal: {"joints": (B, Dq) rad} or {<modality of one of the models>: (B, *out)}."""
        q, qd = self._check_state(q, "q"), self._check_state(qd, "qd", len(q))
        b = len(q)
        self._goal_name, self._goal = self._check_goal(goal, b)
        self._u = torch.zeros(b, 3, self.dq, dtype=torch.float64)                  # (B, 3, Dq) μ, μ', μ''
        self._torque = torch.zeros(b, self.dq, dtype=torch.float64)               # (B, Dq) N·m
        self.failed, self.reasons = np.zeros(b, dtype=bool), [None] * b
        self._mark_nonfinite(q, qd, {}, "at reset")
        ok = torch.from_numpy(~self.failed)
        self._u[ok, 0], self._u[ok, 1] = q[ok], qd[ok]

    def act(self, q: np.ndarray, qd: np.ndarray, observations: Mapping[str, torch.Tensor], dt: float) -> np.ndarray:
        """One control tick: perception update(s), then the action law. → torques (B, Dq) N·m; failed rows: 0."""
        if self._u is None:
            raise RuntimeError("AICController.act before reset: call reset(q, qd, goal) first.")
        b = len(self._u)
        q, qd = self._check_state(q, "q", b), self._check_state(qd, "qd", b)
        obs = self._check_observations(observations, b)
        if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
            raise ValueError(must_be("dt", "a finite control period > 0 in s", dt))
        self._mark_nonfinite(q, qd, obs, "in the sensors")
        rows = torch.from_numpy(np.flatnonzero(~self.failed))
        inputs = _Inputs(q[rows], qd[rows], {k: x[rows] for k, x in obs.items()}, self._goal[rows])
        u = self._u[rows]                                                          # (b, 3, Dq)
        for _ in range(self.config.perception_steps):
            if rows.numel():
                u = u + self._belief_step(u, inputs, dt / self.config.perception_steps)
                rows, u, inputs = self._drop_diverged(rows, u, inputs)
        if rows.numel():
            rate = self.action_rate(u, inputs.q, inputs.qd, inputs.obs)
            torque = (self._torque[rows] + dt * rate).clamp(self._low, self._high)
            self._u[rows], self._torque[rows] = u, torque
            bad = ~torch.isfinite(torque).all(-1)
            self._fail(rows[bad], "torque not finite (a model predicted NaN?)")
        self._torque[torch.from_numpy(self.failed)] = 0.0
        return self._torque.numpy().copy()

    @property
    def belief(self) -> np.ndarray:
        """μ (B, Dq) rad."""
        return self._u[:, 0].numpy().copy()

    @property
    def mu_tilde(self) -> torch.Tensor:
        """(μ, μ', μ'') (B, 3, Dq) in rad, rad/s, rad/s²."""
        return self._u.clone()

    # ---- the law ----------------------------------------------------------------------------------------
    def action_rate(self, mu_tilde: torch.Tensor, q: torch.Tensor, qd: torch.Tensor,
                    observations: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """u̇ = −κ_a [Π_q ε_q + Π_q̇ ε_q̇ + Σ_m J_mᵀ Π_m ε_m] (the AIC action update) at beliefs mu_tilde
        (b, 3, Dq), sensors q, qd (b, Dq) and the extra models' observations (b, *out); float64. → (b, Dq) N·m/s."""
        cfg = self.config
        rate = cfg.pi_q * (q - mu_tilde[:, 0]) + cfg.pi_qd * (qd - mu_tilde[:, 1])
        for _model, eps, pi, jac in self._extra_errors(mu_tilde[:, 0], observations):
            rate = rate + torch.einsum("bod,bo->bd", jac, pi * eps)
        return -cfg.k_a * rate

    def _belief_step(self, u: torch.Tensor, inputs: _Inputs, dt: float) -> torch.Tensor:
        """Δμ̃ for dμ̃/dt = Dμ̃ − κ_μ ∂F/∂μ̃ with Gauss–Newton curvature. (b, 3, Dq) → (b, 3, Dq)."""
        b, k, dq = u.shape
        eps, pi, lin = self._residuals(u, inputs)                                  # (b, R), (b, R), (b, R, 3·Dq)
        lin_t = lin.transpose(1, 2)                                                # (b, 3·Dq, R)
        grad = torch.bmm(lin_t, (pi * eps).unsqueeze(-1)).squeeze(-1)              # (b, 3·Dq) Lᵀ Π ε
        flow = shift(u).reshape(b, k * dq) - self.config.k_mu * grad
        if self.config.integrator == "euler":
            return (dt * flow).reshape(u.shape)
        jac_flow = self._shift - self.config.k_mu * torch.bmm(lin_t, pi.unsqueeze(-1) * lin)   # D − κ_μ LᵀΠL
        return implicit_step(flow, jac_flow, dt).reshape(u.shape)

    def _residuals(self, u: torch.Tensor, inputs: _Inputs):
        """Every term of F stacked: ε (b, R), Π (b, R), L = ∂ε/∂vec μ̃ (b, R, 3·Dq); vec μ̃ is order-major.
        Rows: ε_q = q − μ, ε_q̇ = q̇ − μ', ε_μ = μ' − f(μ), ε_μ' = μ'' − A μ', then ε_m = x_m − g_m(μ)."""
        b, _, dq = u.shape
        f0, a = self._attractor(u[:, 0], inputs)                                   # (b, Dq), (b, Dq, Dq)
        eps = [inputs.q - u[:, 0], inputs.qd - u[:, 1], u[:, 1] - f0,
               u[:, 2] - torch.bmm(a, u[:, 1:2].transpose(1, 2)).squeeze(-1)]
        pi = [self._pi_prop.expand(b, -1)]
        lin = [self._lin_prop.expand(b, -1, -1).clone()]                           # (b, 4·Dq, 3·Dq)
        lin[0][:, 2 * dq:3 * dq, :dq] = -a                                         # ∂ε_μ/∂μ = −A
        lin[0][:, 3 * dq:, dq:2 * dq] = -a                                         # ∂ε_μ'/∂μ' = −A
        for _, e, p, jac in self._extra_errors(u[:, 0], inputs.obs):
            eps.append(e)
            pi.append(p)
            lin.append(torch.cat([-jac, jac.new_zeros(b, jac.shape[1], 2 * dq)], dim=-1))
        return torch.cat(eps, dim=1), torch.cat(pi, dim=1), torch.cat(lin, dim=1)

    def _extra_errors(self, mu: torch.Tensor, observations: Mapping[str, torch.Tensor]):
        """Per extra model with Π > 0: (model, ε = x − g(μ) (b, O), Π (b, O), J (b, O, Dq))."""
        b = mu.shape[0]
        for m in self._live:
            z = model_input(m, mu)
            eps = (observations[m.modality] - m.predict(z).to(mu.dtype)).reshape(b, -1)
            if m.modality in self._fixed:
                pi = torch.full_like(eps, self._fixed[m.modality])
            else:
                pi = m.precision(z).to(mu.dtype).reshape(b, -1) * self.config.model_precision_scale
            yield m, eps, pi, m.jacobian(z).to(mu.dtype)

    def _attractor(self, mu: torch.Tensor, inputs: _Inputs):
        """f(μ) (b, Dq) and A = ∂f/∂μ (b, Dq, Dq) of the goal attractor."""
        beta = dict(self.config.goal_gains).get(self._goal_name, self.config.attractor_gain)
        if self._goal_name == "joints":
            eye = torch.eye(self.dq, dtype=mu.dtype).expand(mu.shape[0], -1, -1)
            return beta * (inputs.goal - mu), -beta * eye
        model = next(m for m in self.models if m.modality == self._goal_name)
        z = model_input(model, mu)
        return attractor_flow(model.predict(z).to(mu.dtype), model.jacobian(z).to(mu.dtype), inputs.goal, beta,
                              self.config.goal_geometry)

    # ---- input checks -----------------------------------------------------------------------------------
    def _check_state(self, x, name: str, batch: int | None = None) -> torch.Tensor:
        arr = np.asarray(x, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != self.dq or (batch is not None and len(arr) != batch):
            want = f"({'B' if batch is None else batch}, {self.dq})"
            raise ValueError(must_be(name, f"an array of shape {want}", arr.shape, "One row per episode."))
        return torch.from_numpy(arr.copy())

    def _check_goal(self, goal, b: int) -> tuple[str, torch.Tensor]:
        shapes = {"joints": (self.dq,), **{m.modality: m.output_shape for m in self.models}}
        if not isinstance(goal, Mapping) or len(goal) != 1 or next(iter(goal)) not in shapes:
            raise ValueError(must_be("goal", f"a dict with one key among {sorted(shapes)}", goal))
        (name, x_d), = goal.items()
        x_d = torch.as_tensor(x_d, dtype=torch.float64)
        if tuple(x_d.shape) != (b, *shapes[name]) or not torch.isfinite(x_d).all():
            raise ValueError(must_be(f"goal[{name!r}]", f"a finite tensor of shape {(b, *shapes[name])}",
                                     tuple(x_d.shape)))
        return name, x_d

    def _check_observations(self, observations, b: int) -> dict[str, torch.Tensor]:
        wanted = {m.modality: (b, *m.output_shape) for m in self._live}          # broken sensors may be absent
        known = {m.modality for m in self.models}
        if not isinstance(observations, Mapping) or not set(wanted) <= set(observations) <= known:
            got = sorted(observations) if isinstance(observations, Mapping) else type(observations).__name__
            raise ValueError(must_be("observations keys", f"the extra models' modalities {sorted(wanted)}", got,
                                     "One (B, *out) tensor per extra model (optional where its precision is 0)."))
        out = {}
        for name, shape in wanted.items():
            x = torch.as_tensor(observations[name], dtype=torch.float64)
            if tuple(x.shape) != shape:
                raise ValueError(must_be(f"observations[{name!r}]", f"of shape {shape}", tuple(x.shape)))
            out[name] = x
        return out

    def _mark_nonfinite(self, q: torch.Tensor, qd: torch.Tensor, obs: Mapping[str, torch.Tensor], when: str):
        for name, x in {"q": q, "qd": qd, **obs}.items():
            bad = ~np.isfinite(x.numpy().reshape(len(x), -1)).all(-1)
            for r in np.flatnonzero(bad & ~self.failed):
                self.failed[r], self.reasons[r] = True, f"non-finite {name} {when}"

    def _drop_diverged(self, rows: torch.Tensor, u: torch.Tensor, inputs: _Inputs):
        """Fail the rows whose belief left the finite, < 1e3 rad region; → the remaining rows, beliefs, inputs."""
        keep = torch.isfinite(u).all(dim=(1, 2)) & (u[:, 0].abs() <= DIVERGED_RAD).all(-1)
        if bool(keep.all()):
            return rows, u, inputs
        self._fail(rows[~keep], "belief diverged (non-finite or beyond 1e3 rad)")
        kept = _Inputs(inputs.q[keep], inputs.qd[keep], {k: x[keep] for k, x in inputs.obs.items()}, inputs.goal[keep])
        return rows[keep], u[keep], kept

    def _fail(self, rows: torch.Tensor, reason: str) -> None:
        for r in rows.tolist():
            self.failed[r], self.reasons[r] = True, reason


def _proprioceptive_terms(cfg: AICConfig, dq: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Π (1, 4·Dq) and the constant part of L (1, 4·Dq, 3·Dq) of the rows ε_q, ε_q̇, ε_μ, ε_μ' (A filled per tick)."""
    eye = torch.eye(dq, dtype=torch.float64)
    lin = torch.zeros(4 * dq, 3 * dq, dtype=torch.float64)
    lin[:dq, :dq] = -eye                                                           # ∂ε_q/∂μ
    lin[dq:2 * dq, dq:2 * dq] = -eye                                               # ∂ε_q̇/∂μ'
    lin[2 * dq:3 * dq, dq:2 * dq] = eye                                            # ∂ε_μ/∂μ'
    lin[3 * dq:, 2 * dq:] = eye                                                    # ∂ε_μ'/∂μ''
    pi = torch.tensor([cfg.pi_q, cfg.pi_qd, cfg.pi_mu, cfg.pi_mu_d], dtype=torch.float64).repeat_interleave(dq)
    return pi[None], lin[None]
