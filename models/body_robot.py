"""The robot of a model's body: the one way every stage (analytic models, benchmarks) finds it.

A shipped robot is found by its name, as it always was. Any other robot travels with the body (`BodySpec.source`):
the robot attrs a store keeps (`datagen.body.attrs`: the record and the model file's text, sha256 and mesh
digests), so a model of a robot from a file, or trained on its store, rebuilds that very robot wherever it is
evaluated. Light at import (no MuJoCo): `training.data` builds bodies from store attrs with it.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from bodyschema.datagen.body.attrs import MODEL_KEY, RECORD_KEY, robot_attrs
from bodyschema.datagen.body.record import SHIPPED, load_record
from bodyschema.models.scaling import BodySpec


def attrs_source(attrs: dict[str, Any]) -> dict | None:
    """The `BodySpec.source` of a robot described by a store's attrs: None for a shipped robot as shipped (its
    name finds it; also a store that predates robot attrs), else the attrs' record and model file."""
    model = attrs.get(MODEL_KEY) or {}         # missing: Robot.from_attrs names what the store lacks
    if RECORD_KEY not in attrs or _as_shipped(str(attrs.get("robot")), attrs[RECORD_KEY], model):
        return None
    return {RECORD_KEY: attrs[RECORD_KEY], MODEL_KEY: model}


def robot_source(robot) -> dict | None:
    """The `BodySpec.source` of a built `Robot` (as its store would record it)."""
    return attrs_source({"robot": robot.name, **robot_attrs(robot)})


def body_robot(body: BodySpec, image_size: tuple[int, int] | None = None, rgb: bool = False,
               actuators: str = "position"):
    """The robot of `body`: the shipped one of its name, else rebuilt from its source. image_size None: the
    record's camera size."""
    from bodyschema.datagen.body.robot import Robot
    return Robot.from_attrs({"robot": body.robot, **(body.source or {})}, image_size=image_size, rgb=rgb,
                            actuators=actuators)


def source_sha256(body: BodySpec) -> str | None:
    """The sha256 of the model file a body's robot was built from; None for a shipped robot (found by name)."""
    return None if body.source is None else body.source[MODEL_KEY].get("sha256")


def _as_shipped(name: str, record: dict, model: dict) -> bool:
    """True when the record and model file are the shipped robot's of that name, unchanged (a robot from a file may
    take a shipped name; a shipped robot seen through another camera is not the shipped one)."""
    if name not in SHIPPED:
        return False
    shipped = load_record(name)
    values = {**record, "model": Path(str(record.get("model"))).name}
    return (values == shipped.to_toml_dict()
            and model.get("sha256") == hashlib.sha256(shipped.model_path.read_bytes()).hexdigest())
