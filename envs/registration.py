"""Gymnasium ids of the reaching environments: one per shipped robot, and a generic one for a robot from a file.

A per-robot id names its robot: `gymnasium.make("bodyschema/Reach-nao_arm-v0", robot="panda")` is refused (it
built a panda under the nao_arm id); only the generic id takes `robot=`.
"""

from __future__ import annotations

import functools

from bodyschema.datagen.body.record import SHIPPED
from bodyschema.errors import must_be

try:
    import gymnasium
except ModuleNotFoundError as missing:         # an optional extra: say which
    raise ModuleNotFoundError(must_be("gymnasium", "installed for bodyschema.envs", "not installed",
                                      "pip install 'bodyschema[envs]'")) from missing

ENTRY_POINT = "bodyschema.envs.reach_env:ReachEnv"
GENERIC_ID = "bodyschema/Reach-v0"            # gymnasium.make(GENERIC_ID, robot="ur5.toml")


def env_id(robot: str) -> str:
    return f"bodyschema/Reach-{robot}-v0"


def reach_named(named: str, robot: str | None = None, **kwargs):
    """The entry point of the id of the shipped robot `named`: a ReachEnv of that robot and no other."""
    from bodyschema.envs.reach_env import ReachEnv
    if robot is not None and robot != named:
        raise ValueError(must_be(f"robot of {env_id(named)}", f"{named!r} (the id names it)", robot,
                                 f"Use gymnasium.make({GENERIC_ID!r}, robot={robot!r}) for another robot."))
    return ReachEnv(robot=named, **kwargs)


def register_envs() -> None:
    """Register every id once (a second import of the package must not warn about re-registration)."""
    if GENERIC_ID not in gymnasium.registry:
        gymnasium.register(id=GENERIC_ID, entry_point=ENTRY_POINT, kwargs={})
    for name in SHIPPED:
        if env_id(name) not in gymnasium.registry:
            gymnasium.register(id=env_id(name), entry_point=functools.partial(reach_named, name),
                               kwargs={"robot": name})
