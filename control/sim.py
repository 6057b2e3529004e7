"""The one batched arm simulator of the benchmarks: B MuJoCo copies of one robot stepped in lockstep.

Per control period: actuation (servo targets or torques, as the robot's `actuation` says) → `mj_step` × substeps
→ `mj_forward`, so site positions and bias forces always belong to the current state. An episode whose
simulation goes non-finite or trips MuJoCo's bad-acceleration warning is marked failed and frozen at its last
finite state. Hooks for the adaptation experiments:
  marker offsets  a displacement (B, 3) m of the visual marker in the hand frame, shown where `shifted` is set
                  (the kinematics are untouched: only what a camera sees moves);
  gravity         `set_gravity(m/s²)` changes the simulated gravity mid-episode (the model is the robot's own:
                  restore it, or use `with ArmBatch(...)`, which puts Earth's back on exit).
"""

from __future__ import annotations

import mujoco
import numpy as np

from bodyschema.datagen.body.robot import GRAVITY
from bodyschema.errors import must_be

DIVERGED = "simulation diverged (bad acceleration)"


def control_substeps(control_hz: float, timestep: float, name: str = "control_hz") -> int:
    """MuJoCo steps per control period; the house error (about the config field `name`) unless the period is a
    whole number of steps."""
    ok = isinstance(control_hz, (int, float)) and np.isfinite(control_hz) and control_hz > 0
    ratio = 1.0 / (control_hz * timestep) if ok else float("nan")
    n = int(round(ratio)) if ok else 0
    if n < 1 or abs(ratio - n) > 1e-6 * n:
        rates = ", ".join(f"{1.0 / (k * timestep):g}" for k in (1, 2, 5, 10, 20))
        raise ValueError(must_be(name, f"a rate whose period is a whole number of MuJoCo steps of "
                                 f"{timestep * 1e3:g} ms", control_hz, f"Use e.g. {rates} Hz."))
    return n


class ArmBatch:
    """B copies of the robot's dynamics (one MjData each) started at rest at q0 (B, Dq) rad.

    hold (position servos only): "pose" sets each servo target to its start joint (the arm sags a little under
    gravity); "gravity" offsets the targets by the gravity torque / servo gain so the arm rests exactly at q0."""

    def __init__(self, robot, q0: np.ndarray, hold: str = "pose", marker_offsets: np.ndarray | None = None):
        self.robot, self.model = robot, robot.model
        self.position = robot.actuation == "position"
        if hold == "gravity":
            _check_servos(robot)
        self.datas = [self._start(q, hold) for q in np.asarray(q0, dtype=np.float64)]
        self.failed = np.zeros(len(self.datas), dtype=bool)
        self.reasons: list[str | None] = [None] * len(self.datas)
        site = self.model.site(robot.ee_site)             # "ee", or the site a record adds on a body + offset
        self._site, self._body = site.id, int(site.bodyid[0])
        self._marker_local = self.model.site_pos[site.id].copy()                       # (3,) m, hand frame
        self.marker_offsets = np.zeros((len(self.datas), 3)) if marker_offsets is None \
            else np.asarray(marker_offsets, dtype=np.float64)                           # (B, 3) m, hand frame
        self.shifted = np.zeros(len(self.datas), dtype=bool)

    def _start(self, q: np.ndarray, hold: str) -> mujoco.MjData:
        m, d = self.model, mujoco.MjData(self.model)
        d.qpos[:] = q
        d.ctrl[:] = q if self.position else 0.0                           # servos hold the start pose
        mujoco.mj_forward(m, d)
        if hold == "gravity":   # at rest on q: servo force gain·ctrl + b1·q = gravity torque qfrc_bias
            d.ctrl[:] = (d.qfrc_bias / m.actuator_gear[:, 0] - m.actuator_biasprm[:, 1] * q) / m.actuator_gainprm[:, 0]
        return d

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.set_gravity(GRAVITY)

    # ---- state --------------------------------------------------------------------------------------------
    @property
    def q(self) -> np.ndarray:
        return np.array([d.qpos for d in self.datas])                     # (B, Dq) rad

    @property
    def qd(self) -> np.ndarray:
        return np.array([d.qvel for d in self.datas])                     # (B, Dq) rad/s

    @property
    def ctrl(self) -> np.ndarray:
        return np.array([d.ctrl for d in self.datas])                     # (B, nu) rad (servos) | N·m (motors)

    @property
    def ee_xyz(self) -> np.ndarray:
        return np.array([d.site_xpos[self._site] for d in self.datas])    # (B, 3) m

    @property
    def marker_xyz(self) -> np.ndarray:
        """(B, 3) m, the visual marker in the world: hand body position + rotation @ (marker point + its offset
        where shifted)."""
        local = self._marker_local + self.marker_offsets * self.shifted[:, None]       # (B, 3) hand frame
        return np.stack([d.xpos[self._body] + d.xmat[self._body].reshape(3, 3) @ p
                         for d, p in zip(self.datas, local)])

    @property
    def shown_offsets(self) -> np.ndarray:
        return self.marker_offsets * self.shifted[:, None]                # (B, 3) m, hand frame

    # ---- dynamics -----------------------------------------------------------------------------------------
    def set_gravity(self, magnitude: float) -> None:
        """Gravity (m/s², pointing down) of every copy from the next step on."""
        self.model.opt.gravity[:] = (0.0, 0.0, -float(magnitude))

    def step(self, ctrl: np.ndarray, substeps: int, skip: np.ndarray | None = None) -> None:
        """Apply ctrl (B, nu) for `substeps` MuJoCo steps; failed episodes (and those in `skip`) stay frozen."""
        for i, d in enumerate(self.datas):
            if self.failed[i] or (skip is not None and skip[i]):
                continue
            qpos, qvel = d.qpos.copy(), d.qvel.copy()
            d.ctrl[:] = ctrl[i]
            for _ in range(substeps):
                mujoco.mj_step(self.model, d)
            if not np.isfinite(d.qpos).all() or d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
                self.failed[i], self.reasons[i] = True, DIVERGED
                d.qpos[:], d.qvel[:] = qpos, qvel                         # freeze at the last finite state
            mujoco.mj_forward(self.model, d)


def _check_servos(robot) -> None:
    m = robot.model
    if not (m.nu == robot.dq and robot.actuation == "position"
            and np.array_equal(m.actuator_trnid[:, 0], np.arange(robot.dq))):
        raise ValueError(must_be(f"the actuators of {robot.name}", "one position servo per joint, in order",
                                 f"{m.nu} {robot.actuation} actuators", "Load the robot with actuators='position'."))
