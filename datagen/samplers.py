"""Where the joint configurations q come from: kinematic samplers (uniform, gaussian) and motor babbling.

Kinematic samplers draw independent poses inside the sampling ranges. Motor babbling is dynamic: the robot's
position actuators track random joint targets, each held for a random duration, under gravity (`mj_step`), and the
trajectory is recorded at a fixed rate in episodes that each start at rest from a random pose, with the targets the
servos track from each recorded sample on (the commands: LeRobot's `action`). All randomness comes from the
`np.random.Generator` passed in. Returned q and targets are float32 (what is stored), clipped to the joint limits.
A diverged simulation (any MuJoCo warning, non-finite or absurd joint velocities) is an error, never data; MuJoCo's
warnings go to our logger instead of a MUJOCO_LOG.TXT in the working folder.
"""

from __future__ import annotations

import logging

import mujoco
import numpy as np

from bodyschema.datagen.store.schema import MAX_JOINT_SPEED
from bodyschema.errors import must_be

logger = logging.getLogger(__name__)
_last_warning = ["none"]  # MuJoCo's latest warning text in this process, quoted by the divergence error


def _on_mujoco_warning(message: str) -> None:
    _last_warning[0] = message.strip()
    logger.debug("MuJoCo: %s", _last_warning[0])  # one per step once diverged: the error says it, once


def route_mujoco_warnings() -> None:
    """Send MuJoCo's warnings to our logger (its default also appends them to MUJOCO_LOG.TXT in the cwd)."""
    if mujoco.get_mju_user_warning() is None:  # leave a handler someone else installed
        mujoco.set_mju_user_warning(_on_mujoco_warning)


def uniform(rng: np.random.Generator, ranges: np.ndarray, n: int) -> np.ndarray:
    """n poses uniform in the box `ranges` (Dq, 2) rad -> (n, Dq) float64."""
    lo, hi = ranges[:, 0], ranges[:, 1]
    return lo + (hi - lo) * rng.random((n, len(lo)))  # (n, Dq)


def gaussian(rng: np.random.Generator, ranges: np.ndarray, n: int) -> np.ndarray:
    """n poses ~ N(range centre, (range / 6)^2) per joint, clipped to the range -> (n, Dq) float64."""
    lo, hi = ranges[:, 0], ranges[:, 1]
    q = (lo + hi) / 2 + (hi - lo) / 6 * rng.standard_normal((n, len(lo)))  # (n, Dq); +-3 sigma spans the range
    return np.clip(q, lo, hi)


KINEMATIC = {"uniform": uniform, "gaussian": gaussian}


def to_stored_q(q: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Cast to the stored float32 and clip to the joint limits (Dq, 2), so stored q is exactly what is observed."""
    return np.clip(q.astype(np.float32), limits[:, 0].astype(np.float32), limits[:, 1].astype(np.float32))


def sample_kinematic(sampler: str, rng: np.random.Generator, ranges: np.ndarray, limits: np.ndarray,
                     n: int) -> np.ndarray:
    """n poses from the named kinematic sampler -> (n, Dq) float32 within `limits`."""
    if sampler not in KINEMATIC:
        raise ValueError(must_be("sampler", f"one of {tuple(KINEMATIC)}", sampler))
    return to_stored_q(KINEMATIC[sampler](rng, np.asarray(ranges, float), n), np.asarray(limits, float))


class Babbler:
    """Motor babbling on one robot: position targets held for random durations, simulated with `mj_step`.

    Uses its own `MjData` (the robot's is left to `observe`). `record_hz` is realised as a whole number of
    physics steps (`stride`); `rate_hz` is the rate actually used (stored in the attrs).
    """

    def __init__(self, model: mujoco.MjModel, joint_names: list[str], limits: np.ndarray, record_hz: float,
                 hold_s: tuple[float, float]):
        self.model = model
        self.data = mujoco.MjData(model)
        self.limits = np.asarray(limits, float)  # (Dq, 2) rad
        joint_ids = [model.joint(name).id for name in joint_names]
        self.qadr = np.array([model.jnt_qposadr[j] for j in joint_ids])
        self.dadr = np.array([model.jnt_dofadr[j] for j in joint_ids])
        self.act = np.array([self._position_actuator(j, name) for j, name in zip(joint_ids, joint_names)])
        dt = model.opt.timestep
        self.stride = max(1, round(1.0 / (record_hz * dt)))  # physics steps between recorded samples
        self.rate_hz = 1.0 / (self.stride * dt)
        self.hold_steps = (max(1, round(hold_s[0] / dt)), max(1, round(hold_s[1] / dt)))
        touch = [s for s in range(model.nsensor) if model.sensor_type[s] == mujoco.mjtSensor.mjSENS_TOUCH]
        self.touch_adr = int(model.sensor_adr[touch[0]]) if touch else None  # contact force (N) during babbling
        route_mujoco_warnings()

    def _position_actuator(self, joint_id: int, name: str) -> int:
        m = self.model
        for a in range(m.nu):
            if (m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and m.actuator_trnid[a, 0] == joint_id
                    and m.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE):  # a servo: ctrl is a target angle
                return a
        raise ValueError(must_be(f"joint {name!r}", "driven by a position actuator for babbling", "no actuator",
                                 "Load the robot with actuators='position' or use a kinematic sampler."))

    def episode(self, rng: np.random.Generator, ranges: np.ndarray, n: int) -> dict[str, np.ndarray]:
        """One episode of n recorded samples, starting at rest from a random pose in `ranges` (Dq, 2) rad.

        Returns q (n, Dq) float32 rad, qvel (n, Dq) float32 rad/s, t (n,) float32 s since the episode start,
        target (n, Dq) float32 rad, the servo targets (ctrl) the arm is driven toward from that sample on (a target
        switched at that very instant counts: it is the command given after observing the sample, LeRobot's
        `action`), and touch (n, 1) float32 N, the simulated contact force at that instant, when the robot has a
        touch sensor. Recording the targets draws nothing from `rng`: q and the rest are as without them.
        """
        m, d = self.model, self.data
        lo, hi = ranges[:, 0], ranges[:, 1]
        mujoco.mj_resetData(m, d)  # fresh state (and warm start) per episode: deterministic given rng
        start = rng.uniform(lo, hi)
        d.qpos[self.qadr] = start
        d.ctrl[self.act] = start
        mujoco.mj_forward(m, d)
        q, qvel, target = np.empty((n, len(lo))), np.empty((n, len(lo))), np.empty((n, len(lo)))
        t, touch = np.empty(n), np.empty((n, 1))
        step, next_switch = 0, 0
        for k in range(n):
            q[k], qvel[k], t[k] = d.qpos[self.qadr], d.qvel[self.dadr], d.time
            if self.touch_adr is not None:
                mujoco.mj_forward(m, d)  # sensors of the current state (mj_step leaves the pre-step values)
                touch[k, 0] = d.sensordata[self.touch_adr]
            record_at = step + self.stride
            while step < record_at:  # advance to the next recording, switching targets on the way
                if step >= next_switch:
                    d.ctrl[self.act] = rng.uniform(lo, hi)
                    next_switch = step + int(rng.integers(self.hold_steps[0], self.hold_steps[1] + 1))
                if step + self.stride == record_at:  # the first step after sample k: the target it moves toward
                    target[k] = d.ctrl[self.act]
                nstep = min(record_at, next_switch) - step
                mujoco.mj_step(m, d, nstep)
                step += nstep
        self._check_stable(qvel)
        out = {"q": to_stored_q(q, self.limits), "qvel": qvel.astype(np.float32), "t": t.astype(np.float32),
               "target": to_stored_q(target, self.limits)}
        if self.touch_adr is not None:
            out["touch"] = touch.astype(np.float32)
        return out

    def _check_stable(self, qvel: np.ndarray) -> None:
        """Raise FloatingPointError if this episode warned (MuJoCo resets a diverged state and goes on) or its joint
        velocities `qvel` (n, Dq) rad/s are non-finite or beyond MAX_JOINT_SPEED."""
        warned = {mujoco.mjtWarning(i).name: int(self.data.warning[i].number)
                  for i in range(int(mujoco.mjtWarning.mjNWARNING)) if self.data.warning[i].number}
        with np.errstate(invalid="ignore"):
            speed = float(np.abs(qvel).max())
        if warned or not speed <= MAX_JOINT_SPEED:
            raise FloatingPointError(must_be(
                "the babbling simulation", f"stable (no MuJoCo warning, |qvel| <= {MAX_JOINT_SPEED:g} rad/s)",
                f"warnings {warned}, max |qvel| {speed:.3g} rad/s; last MuJoCo warning: {_last_warning[0]}",
                "Lower --gravity (9.81 on Earth) or check the robot's model; nothing diverged was stored."))

    def episodes(self, rng: np.random.Generator, ranges: np.ndarray, lengths: list[int],
                 first_episode: int) -> dict[str, np.ndarray]:
        """Consecutive episodes of the given lengths; adds `episode` (int32 global index) to the arrays."""
        parts = [self.episode(rng, np.asarray(ranges, float), n) for n in lengths]
        out = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        out["episode"] = np.repeat(np.arange(first_episode, first_episode + len(lengths), dtype=np.int32), lengths)
        return out
