"""A robot's reaching defaults, read from its robot record's [reaching] table (one place per robot, issue 20).

models (modalities of its analytic defaults), control_hz (Hz), duration_s (s), actuators ("position": servos,
"torque": motors) and action (the velocity controller's tuned gains, `aif.action.ActionConfig` fields). A record
without the table (a robot from a file) gets DEFAULTS: ee_xyz + joints at 50 Hz for 3 s on position servos.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from bodyschema.aif.action import ActionConfig
from bodyschema.errors import must_be

DEFAULTS = {"models": ("ee_xyz", "joints"), "control_hz": 50.0, "duration_s": 3.0, "actuators": "position"}


@dataclass(frozen=True)
class ReachingDefaults:
    models: tuple[str, ...]       # analytic:<robot>:<modality> specs
    control_hz: float
    duration_s: float
    actuators: str                # what the benchmark loads the robot with
    action: ActionConfig | None   # the robot's tuned velocity controller; None: ActionConfig()


@functools.cache
def reaching_defaults(robot: str) -> ReachingDefaults:
    """The [reaching] values of a robot reference (a shipped name or a file), DEFAULTS where absent."""
    from bodyschema.datagen.body.robot import robot_record
    values = {**DEFAULTS, **robot_record(robot).reaching}
    if values["actuators"] not in ("position", "torque"):
        raise ValueError(must_be(f"[reaching] actuators of {robot}", "'position' or 'torque'", values["actuators"]))
    action = ActionConfig(**values["action"]) if values.get("action") else None
    return ReachingDefaults(tuple(f"analytic:{robot}:{m}" for m in values["models"]), float(values["control_hz"]),
                            float(values["duration_s"]), values["actuators"], action)
