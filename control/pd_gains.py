"""The PD baseline's gains, derived from the arm's own model and the control period (issue 33, item 5).

The rule ("model"): a computed-torque PD, every joint critically damped at one bandwidth ω,
    τ = M(q) · s·(ω² (q_d − q) − 2ζω q̇) + b(q, q̇) − p(q) + f ⊙ sat((q_d − q) / ε)
  M(q)      the joint-space inertia at the sensed pose (`mj_fullM`: link inertias and armature), so the stiffness
            K_p(q) = ω² M(q) follows the arm's inertia at every pose, off-diagonal coupling included;
  ω         min(OMEGA_MAX, RATE_FRACTION / Δt): the control period Δt bounds it. A double integrator under this
            law with a zero-order hold keeps real closed-loop poles up to ω·Δt = 0.5 and goes unstable at 1
            (eigenvalues of the sampled loop: ρ = 0.74 per tick at 0.4); OMEGA_MAX is the project's servo
            bandwidth (`infer.SERVO_RAD_S`), what the inferred servos were built for;
  s ∈ [0, 1] scales the whole acceleration so that τ fits the torque limits (the direction of the joint
            acceleration is kept; clipping joint by joint breaks the decoupling that M(q) buys);
  b(q, q̇)   `qfrc_bias`: gravity (under the configured gravity, a private copy of the model) + Coriolis;
  p(q)      `qfrc_passive` at q̇ = 0: springs and the like; joint damping is left to damp;
  f         the joints' dry friction (`dof_frictionloss`): without it a joint sticks wherever ω² M_jj |e| < f_j
            (TALOS's wrists: 1 N·m at M ω² = 9 N·m/rad, 6° off); with it, inside e < ε/11 at most.
            ε = FRICTION_WIDTH · f / (ω² M_jj), a smooth sign that does not chatter.
Why not the old rule (diagonal K_p = ω² · the joint's largest diagonal inertia, critically damped for it): where
the inertia is smaller (a UR5's shoulder pan: 0.46 of 4.4 kg·m²) the effective bandwidth is √(4.4/0.46)·20 = 62
rad/s, ω·Δt = 1.2 at 50 Hz: the sampled loop oscillates and never settles (UR5: 20 % within 10 mm in 3 s; 100 %
with the same gains at 500 Hz).
"""

from __future__ import annotations

import mujoco
import numpy as np

from bodyschema.datagen.body.infer import SERVO_RAD_S, inertia_gains

OMEGA_MAX = SERVO_RAD_S     # rad/s, the bandwidth where the control rate allows it (the inferred servos' ω)
RATE_FRACTION = 0.4         # ω·Δt at most: the sampled loop's poles stay real (≤ 0.5) with a margin
DAMPING_RATIO = 1.0         # ζ: critically damped, no overshoot into a joint limit
FRICTION_WIDTH = 0.1        # ε as a fraction of the band where PD alone sticks on dry friction
INFERRED_DRIFT = 1.5        # a [pd] kp within this factor of the model's I·ω² (and kd = 2kp/ω) is robot init's


def bandwidth(dt: float) -> float:
    """ω rad/s for a control period dt s (dt ≤ 0: unknown, OMEGA_MAX)."""
    return OMEGA_MAX if dt <= 0 else min(OMEGA_MAX, RATE_FRACTION / dt)


def inferred_pd(robot) -> bool:
    """Whether the record's [pd] is only what `bodyschema robot init` inferred (`infer.inertia_gains` without
    sag), not gains someone tuned (the Panda's libfranka gains). The inferred rule leaves two marks: kd = 2·kp/ω
    on every joint (kp = I·ω², kd = 2√(kp·I)), whatever the model, and kp within INFERRED_DRIFT of this model's
    own I·ω². The first survives a model that changed since `robot init` (mass lower bounds, meshes, MuJoCo's
    inertia), which an exact recomputation did not; the second tells a hand tuning that is also critically
    damped at ω (kp = 100, kd = 10) from the inferred gains."""
    pd = robot.record.pd
    if not pd:
        return True
    kp, kd = np.asarray(pd["kp"], dtype=float), np.asarray(pd["kd"], dtype=float)
    ours, _ = inertia_gains(robot.model, robot.workspaces["full"], sag=False)
    if len(kp) != len(ours) or len(kd) != len(ours):
        return False
    signature = np.allclose(kd, 2.0 * kp / SERVO_RAD_S, rtol=1e-4, atol=1e-5)
    drift = np.abs(np.log(np.maximum(kp, 1e-12) / np.asarray(ours)))     # |ln(kp / I·ω²)| per joint
    return bool(signature and np.all(drift <= np.log(INFERRED_DRIFT)))


class ModelLaw:
    """The rule above on one MuJoCo model (the PD's private copy); `torque` is batched over B episodes."""

    def __init__(self, model: mujoco.MjModel, torque_limits: np.ndarray):
        self.model, self.data = model, mujoco.MjData(model)
        self.low, self.high = torque_limits.T                                 # (Dq,) N·m
        self.friction = model.dof_frictionloss.copy()                         # (Dq,) N·m
        self._full = np.zeros((model.nv, model.nv))

    def gains(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(K_p, K_d) at pose q (Dq,) rad: ω² M(q) N·m/rad and 2ζω M(q) N·m·s/rad, each (Dq, Dq)."""
        w, inertia = bandwidth(dt), self._inertia(q)
        return w * w * inertia, 2.0 * DAMPING_RATIO * w * inertia

    def torque(self, error: np.ndarray, q: np.ndarray, qd: np.ndarray, qd_ref: np.ndarray | None,
               dt: float) -> np.ndarray:
        """τ (B, Dq) N·m for error = q_d − q, the sensed q, q̇ and a velocity reference (None: 0), all (B, Dq)."""
        w = bandwidth(dt)
        m, d = self.model, self.data
        out = np.empty_like(q)
        for i in range(len(q)):
            inertia = self._inertia(q[i])                                     # also leaves d at (q, 0)
            rest = d.qfrc_passive.copy()                                      # p(q)
            d.qvel[:] = qd[i]
            mujoco.mj_fwdVelocity(m, d)                                       # b(q, q̇)
            ref = 0.0 if qd_ref is None else qd_ref[i]
            accel = w * w * error[i] - 2.0 * DAMPING_RATIO * w * (qd[i] - ref)   # (Dq,) rad/s²
            push = inertia @ accel
            hold = d.qfrc_bias - rest
            out[i] = self._fit(push, hold) + hold + self._friction(error[i], np.diag(inertia), w)
        return np.clip(out, self.low, self.high)

    def _inertia(self, q: np.ndarray) -> np.ndarray:
        m, d = self.model, self.data
        d.qpos[:], d.qvel[:] = q, 0.0
        mujoco.mj_fwdPosition(m, d)
        mujoco.mj_fwdVelocity(m, d)
        mujoco.mj_fullM(m, d, self._full)
        return self._full.copy()                                              # (Dq, Dq) kg·m²

    def _fit(self, push: np.ndarray, hold: np.ndarray) -> np.ndarray:
        """push scaled by the largest s ∈ [0, 1] with s·push + hold inside the torque limits."""
        room = np.where(push > 0, self.high - hold, self.low - hold)
        moving = np.abs(push) > 1e-12
        scale = np.clip(np.min(room[moving] / push[moving]), 0.0, 1.0) if moving.any() else 1.0
        return scale * push

    def _friction(self, error: np.ndarray, inertia_diag: np.ndarray, w: float) -> np.ndarray:
        width = FRICTION_WIDTH * self.friction / np.maximum(w * w * inertia_diag, 1e-12)   # ε (Dq,) rad
        return self.friction * np.clip(error / np.maximum(width, 1e-12), -1.0, 1.0)
