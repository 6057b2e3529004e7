"""The baseline ("built-in") joint controller of the torque-driven arms: PD plus model compensation tuned on Earth.

Two laws, both clipped to the torque limits, both with their model on a private copy of the MJCF under Earth
gravity (9.81 m/s²), so changing the simulated gravity (the Jupiter experiment) leaves the compensation wrong, as
it would be on a real robot whose dynamic model was identified on Earth:
  "record"  τ = K_p (q_d − q) − K_d q̇ + g_⊕(q)   diagonal gains someone tuned: the record's [pd] (the Panda's:
            libfranka's joint impedance example) or PDConfig's kp, kd; g_⊕ = `qfrc_bias` at q̇ = 0.
  "model"   the rule of `pd_gains` (issue 33): gains derived from the arm's own model and the control period, no
            per-arm constant: τ = M(q)·s·(ω²(q_d − q) − 2ζω q̇) + b(q, q̇) − p(q) + friction, with
            ω = min(20 rad/s, 0.4 / Δt), s fitting τ into the torque limits, b the bias (gravity + Coriolis), p the
            springs, the friction the joints' own dry friction. Every joint critically damped at ω at every pose.
PDConfig.gains "auto" takes "record" where the record's [pd] was tuned and "model" where there is none or it is
what `robot init` inferred (`pd_gains.inferred_pd`): those diagonal gains, sized for each joint's largest
inertia, oscillated at 50 Hz wherever the inertia is smaller (a UR5: 20 % of goals within 10 mm, TALOS's left
arm 0 %; the model rule: 100 % on both, bench/pd_baseline.py).
Same interface as `aif.aic.AICController` (reset / act / failed / reasons), so benchmarks drive both through one
loop; act's dt (s, the control period) sets the model rule's ω.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from bodyschema.control.pd_gains import ModelLaw, inferred_pd
from bodyschema.datagen.body.robot import GRAVITY, Robot
from bodyschema.errors import must_be

GAINS = ("auto", "record", "model")


@dataclass(frozen=True)
class PDConfig:
    kp: tuple[float, ...] | None = None    # N·m/rad per joint; None: the robot record's [pd] (else inferred)
    kd: tuple[float, ...] | None = None    # N·m·s/rad per joint; None: as kp
    gravity: float = GRAVITY               # m/s², the gravity the compensation model was identified under
    gains: str = "auto"                    # "record" | "model" (module docstring) | "auto": record if tuned

    def __post_init__(self):
        if self.gains not in GAINS:
            raise ValueError(must_be("gains", f"one of {GAINS}", self.gains))
        if self.kp is not None and self.gains == "model":
            raise ValueError(must_be("gains", "'auto' or 'record' when kp and kd are given", self.gains))
        if (self.kp is None) != (self.kd is None):
            raise ValueError(must_be("kp and kd", "both given or both None (the robot's gains)", (self.kp, self.kd)))
        for name in ("kp", "kd") if self.kp is not None else ():
            gains = np.asarray(getattr(self, name), dtype=float)
            if gains.ndim != 1 or not np.isfinite(gains).all() or (gains < 0).any():
                raise ValueError(must_be(name, "a tuple of finite gains ≥ 0, one per joint", getattr(self, name)))
        if self.kp is not None and len(self.kp) != len(self.kd):
            raise ValueError(must_be("kd", f"as long as kp ({len(self.kp)} joints)", len(self.kd)))
        if not (np.isfinite(self.gravity) and self.gravity >= 0):
            raise ValueError(must_be("gravity", "a finite magnitude ≥ 0 in m/s²", self.gravity))


class PDController:
    """PD + Earth-model compensation for a torque-driven robot (a name, path, record or `Robot`: its record and
    model text, so a robot rebuilt from a store or a model's body needs no file), batched over B episodes."""

    def __init__(self, robot, config: PDConfig = PDConfig()):
        given = {"robot": robot.record, "text": robot.source.text} if isinstance(robot, Robot) else {"robot": robot}
        self._robot = Robot.load(**given, actuators="torque", gravity=config.gravity)   # private model: g_⊕ only
        self._data = mujoco.MjData(self._robot.model)
        self.dq = self._robot.dq
        self.config = config
        self.torque_limits = self._robot.model.actuator_ctrlrange.copy()          # (Dq, 2) N·m
        if self._robot.model.nu != self.dq:
            raise ValueError(must_be(f"robot {self._robot.name!r}", f"a motor on each of its {self.dq} joints for the "
                                     "PD baseline", f"{self._robot.model.nu} actuators",
                                     "Give the record [actuators] (`bodyschema robot init` infers servos)."))
        self.law = config.gains if config.gains != "auto" else \
            "record" if config.kp is not None or not inferred_pd(self._robot) else "model"
        if self.law == "record":
            kp, kd = (config.kp, config.kd) if config.kp is not None else robot_gains(self._robot)
            if len(kp) != self.dq or len(kd) != self.dq:
                raise ValueError(must_be("the PD gains kp and kd", f"{self.dq} gains each, one per joint of "
                                         f"{self._robot.name}", (len(kp), len(kd)), "Fix [pd] in its record."))
            self._kp, self._kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)
        else:
            self._model_law = ModelLaw(self._robot.model, self.torque_limits)
        self._goal = None
        self.failed, self.reasons = np.zeros(0, dtype=bool), []

    def reset(self, q: np.ndarray, qd: np.ndarray, goal: Mapping[str, np.ndarray]) -> None:
        """goal: {"joints": (B, Dq) rad}; q, qd (B, Dq) rad, rad/s."""
        q = self._check(q, "q")
        if not isinstance(goal, Mapping) or set(goal) != {"joints"}:
            raise ValueError(must_be("goal", "{'joints': (B, Dq) rad}", goal, "The PD baseline tracks joint goals."))
        self._goal = self._check(np.asarray(goal["joints"], dtype=float), "goal['joints']", len(q))
        if not np.isfinite(self._goal).all():
            raise ValueError(must_be("goal['joints']", "finite", "NaN or inf"))
        self.failed, self.reasons = np.zeros(len(q), dtype=bool), [None] * len(q)

    def act(self, q: np.ndarray, qd: np.ndarray, observations: Mapping | None = None, dt: float = 0.0,
            qd_ref: np.ndarray | None = None) -> np.ndarray:
        """τ (B, Dq) N·m for the sensed q, q̇ (B, Dq) and a velocity reference qd_ref (B, Dq) rad/s (None: rest);
        dt s is the control period (the model rule's ω; ≤ 0: 20 rad/s); observations are unused (interface of
        AICController)."""
        if self._goal is None:
            raise RuntimeError("PDController.act before reset: call reset(q, qd, goal) first.")
        q, qd = self._check(q, "q", len(self._goal)), self._check(qd, "qd", len(self._goal))
        for name, x in (("q", q), ("qd", qd)):
            for r in np.flatnonzero(~np.isfinite(x).all(-1) & ~self.failed):
                self.failed[r], self.reasons[r] = True, f"non-finite {name} in the sensors"
        torque = np.zeros_like(q)
        ok = ~self.failed
        if ok.any():
            ref = None if qd_ref is None else self._check(qd_ref, "qd_ref", len(q))[ok]
            if self.law == "model":
                torque[ok] = self._model_law.torque(self._goal[ok] - q[ok], q[ok], qd[ok], ref, dt)
                return torque
            damped = qd[ok] if ref is None else qd[ok] - ref
            tau = self._kp * (self._goal[ok] - q[ok]) - self._kd * damped + self.gravity_torque(q[ok])
            torque[ok] = np.clip(tau, self.torque_limits[:, 0], self.torque_limits[:, 1])
        return torque

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """g(q) (N, Dq) N·m under the configured gravity: the bias force at rest."""
        m, d = self._robot.model, self._data
        out = np.empty_like(q)
        d.qvel[:] = 0.0
        for q_i, out_i in zip(q, out):
            d.qpos[:] = q_i
            mujoco.mj_fwdPosition(m, d)
            mujoco.mj_fwdVelocity(m, d)                                          # qfrc_bias = RNE at q̇ = 0
            out_i[:] = d.qfrc_bias
        return out

    def _check(self, x, name: str, batch: int | None = None) -> np.ndarray:
        arr = np.asarray(x, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != self.dq or (batch is not None and len(arr) != batch):
            raise ValueError(must_be(name, f"an array of shape ({'B' if batch is None else batch}, {self.dq})",
                                     arr.shape))
        return arr


def robot_gains(robot: Robot) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(kp, kd) of the robot's record [pd], else the old rule (`infer.inertia_gains`: each joint's largest
    diagonal inertia × (20 rad/s)², critically damped), what PDConfig(gains="record") runs without [pd]."""
    if robot.record.pd:
        return tuple(robot.record.pd["kp"]), tuple(robot.record.pd["kd"])
    from bodyschema.datagen.body.infer import inertia_gains
    kp, kd = inertia_gains(robot.model, robot.workspaces["full"], sag=False)
    return tuple(kp), tuple(kd)
