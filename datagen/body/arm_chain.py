"""`infer_arm`: which end effector and which hinges of a model file make "the arm" (`robot init`'s choice).

- ee: the model's site `ee`; else the body ending the longest arm chain, preferring a body named like a hand, wrist
  or tool (HAND) over any other (a humanoid's legs and head are chains too); ties go to the deeper body, then to the
  one first in the file. Its first site is the ee, else the body itself at a zero offset.
- an arm chain: the hinges from the last branching body above the ee (a torso holding two arms and a head, a pelvis
  holding legs) down to it, so a humanoid's arm leaves its torso and legs out; on a serial arm, every hinge from the
  world. Finger joints (named like FINGER) and mimic joints (a URDF <mimic>: a joint equality's follower) are never
  part of one, and a body below them is never the ee.
- `ee` given (a body or a site): the arm chain up to it, finger joints on its path included (mimic ones not).
- `joints` given: those joints; the ee, unless given, the body the rule above picks among those below every given
  joint with no other hinge on the way.
"""

from __future__ import annotations

import re

import mujoco
import numpy as np

from bodyschema.errors import must_be

HAND = re.compile(r"hand|wrist|tool|gripper|palm|tcp|flange|effector|eef|grasp|(^|[_\W])ee($|[_\W])", re.I)
FINGER = re.compile(r"finger|thumb|knuckle|phalan|gripper|claw|jaw|digit|pinky|little|index|middle", re.I)
_HINGE = mujoco.mjtJoint.mjJNT_HINGE


def infer_arm(model: mujoco.MjModel, ee: str | None = None, joints: tuple[str, ...] = ()
              ) -> tuple[dict, int, list[str]]:
    """({site} | {body, offset}, the ee's body id, the arm's hinges world first); see the module docstring."""
    arm = _arm_hinges(model)
    if joints:
        _check_joints(model, joints)
    if ee is not None:
        body, found = _named(model, ee)
    elif not joints and "ee" in _names(model, "site"):
        body, found = int(model.site("ee").bodyid[0]), {"site": "ee"}
    else:
        body, found = _pick(model, arm, joints), None
    if joints:
        chosen = list(joints)
    else:
        allowed = arm | {j for j in _path_joints(model, body) if not _mimic(model, j)} if ee is not None else arm
        chosen = _chain(model, body, allowed, arm)
    if found is None:
        own = [s for s in range(model.nsite) if model.site_bodyid[s] == body and model.site(s).name]
        found = {"site": model.site(own[0]).name} if own else {"body": model.body(body).name, "offset": [0.0] * 3}
    return found, body, chosen


def _names(model: mujoco.MjModel, kind: str) -> list[str]:
    return [getattr(model, kind)(i).name for i in range(getattr(model, f"n{kind}"))]


def _mimic(model: mujoco.MjModel, joint: int) -> bool:
    """A joint that follows another through a joint equality (how MuJoCo reads a URDF <mimic>)."""
    return any(model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj1id[e] == joint and model.eq_obj2id[e] >= 0
               for e in range(model.neq))


def _finger(model: mujoco.MjModel, joint: int) -> bool:
    return bool(FINGER.search(model.joint(joint).name)) or _mimic(model, joint)


def _arm_hinges(model: mujoco.MjModel) -> set[int]:
    return {j for j in range(model.njnt) if model.jnt_type[j] == _HINGE and not _finger(model, j)}


def _path(model: mujoco.MjModel, body: int) -> list[int]:
    bodies = []
    while body != 0:
        bodies.append(body)
        body = int(model.body_parentid[body])
    return bodies[::-1]


def _path_joints(model: mujoco.MjModel, body: int) -> list[int]:
    return [int(j) for b in _path(model, body) for j in np.flatnonzero(model.jnt_bodyid == b)]


def _chain(model: mujoco.MjModel, body: int, allowed: set[int], arm: set[int]) -> list[str]:
    """The hinges in `allowed` on the path to `body` below its last branching body (one whose children lead to
    hinges of `arm` along more than one of them)."""
    leads = np.zeros(model.nbody, bool)                   # the body's subtree (itself included) holds an arm hinge
    for j in arm:
        for b in _path(model, int(model.jnt_bodyid[j])):
            leads[b] = True
    children = np.zeros(model.nbody, int)
    for b in range(1, model.nbody):
        children[model.body_parentid[b]] += leads[b]
    path = _path(model, body)
    start = max((i + 1 for i, b in enumerate(path[:-1]) if children[b] > 1), default=0)
    return [model.joint(j).name for b in path[start:] for j in np.flatnonzero(model.jnt_bodyid == b)
            if model.jnt_type[j] == _HINGE and j in allowed]


def _pick(model: mujoco.MjModel, arm: set[int], joints: tuple[str, ...]) -> int:
    given = {model.joint(name).id for name in joints}
    best, key = None, None
    for body in range(1, model.nbody):
        path = _path_joints(model, body)
        hinges = [j for j in path if model.jnt_type[j] == _HINGE]
        if given:
            last = max(path.index(j) for j in given) if given <= set(path) else None
            if last is None or any(model.jnt_type[j] == _HINGE for j in path[last + 1:]):
                continue                                 # not below every given joint, or another hinge after them
            length = len(given)
        else:
            if not hinges or any(j not in arm for j in hinges) or any(_finger(model, j) for j in path):
                continue                                 # on the world, or below a finger or a mimic joint
            length = len(_chain(model, body, arm, arm))
        candidate = (bool(HAND.search(model.body(body).name)), length, len(_path(model, body)), -body)
        if length and (key is None or candidate > key):
            best, key = body, candidate
    if best is None:
        raise ValueError(must_be("the model's arm", "a chain of hinge joints from the world to a body",
                                 "no body below a hinge" + (f" and every one of {list(joints)}" if joints else ""),
                                 "Name the end effector with --ee and the joints with --joints."))
    return best


def _named(model: mujoco.MjModel, name: str) -> tuple[int, dict]:
    if name in _names(model, "site"):
        return int(model.site(name).bodyid[0]), {"site": name}
    bodies = [b for b in _names(model, "body") if b and b != "world"]
    if name not in bodies:
        raise ValueError(must_be("--ee", "a body or site of the model", name,
                                 f"Bodies: {bodies[:40]}{' ...' if len(bodies) > 40 else ''}."))
    return model.body(name).id, {"body": name, "offset": [0.0] * 3}


def _check_joints(model: mujoco.MjModel, joints: tuple[str, ...]) -> None:
    hinges = [model.joint(j).name for j in range(model.njnt) if model.jnt_type[j] == _HINGE]
    bad = [name for name in joints if name not in hinges]
    if bad or len(set(joints)) != len(joints):
        raise ValueError(must_be("--joints", "distinct hinge joints of the model", bad or list(joints),
                                 f"Hinges: {hinges[:40]}{' ...' if len(hinges) > 40 else ''}."))
