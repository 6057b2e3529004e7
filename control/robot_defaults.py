"""A robot's reaching defaults, read from its robot record's [reaching] table (one place per robot, issue 20).

models (modalities of its analytic defaults), control_hz (Hz), duration_s (s), actuators ("position": servos,
"torque": motors) and action (the velocity controller's tuned gains, `aif.action.ActionConfig` fields). A record
without the table (a robot from a file) gets DEFAULTS: ee_xyz + joints at 50 Hz for 3 s on position servos.
The record holds the table as given: its keys are this benchmark's vocabulary, so they are checked here, when the
reaching benchmark (or the Gymnasium env) reads them, with the house line naming the key.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from bodyschema.aif.action import ActionConfig
from bodyschema.errors import must_be

DEFAULTS = {"models": ("ee_xyz", "joints"), "control_hz": 50.0, "duration_s": 3.0, "actuators": "position"}
KEYS = ("models", "control_hz", "duration_s", "actuators", "action")


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
    from bodyschema.datagen.body.infer import robot_record
    reaching = robot_record(robot).reaching
    problems = reaching_problems(reaching, robot)
    if problems:
        raise ValueError("\n".join(problems))
    values = {**DEFAULTS, **reaching}
    action = ActionConfig(**values["action"]) if values.get("action") else None
    return ReachingDefaults(tuple(f"analytic:{robot}:{m}" for m in values["models"]), float(values["control_hz"]),
                            float(values["duration_s"]), values["actuators"], action)


def reaching_problems(reaching: dict, robot: str) -> list[str]:
    """Every problem of a record's [reaching] table (of `robot`, a reference), as house lines naming the key."""
    extra = sorted(set(reaching) - set(KEYS))
    if extra:
        return [must_be(f"[reaching] of {robot}", f"keys among {list(KEYS)}", extra)]
    p = []
    for key, unit in (("control_hz", "Hz"), ("duration_s", "s")):
        value = reaching.get(key, 1.0)
        if not (_finite(value) and value > 0):
            p.append(must_be(f"record [reaching] {key}", f"a finite number > 0 ({unit})", value))
    models = reaching.get("models", [])
    if not (isinstance(models, list) and all(isinstance(m, str) and m for m in models)):
        p.append(must_be("record [reaching] models", "a list of modalities, e.g. [\"ee_xyz\", \"joints\"]", models))
    if reaching.get("actuators", "position") not in ("position", "torque"):
        p.append(must_be("record [reaching] actuators", "'position' or 'torque'", reaching.get("actuators")))
    if not isinstance(reaching.get("action", {}), dict):
        p.append(must_be("record [reaching] action", "a table of velocity controller settings", reaching["action"]))
    return p


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
