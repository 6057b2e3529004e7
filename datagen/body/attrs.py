"""A store's robot, self-contained: the record and the model file (text, sha256, mesh digests) in the root attrs.

`robot_attrs(robot)` is what `generate` writes; `record_of_attrs(attrs)` gives back the record and the model text,
so `Robot.from_attrs` rebuilds the store's robot without the model file (meshes, when the model has any, are read
from where they were and checked against their digests). Older stores, without these attrs, name a shipped robot.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bodyschema.datagen.body.record import RobotRecord, load_record, record_from_dict
from bodyschema.errors import must_be

RECORD_KEY, MODEL_KEY = "robot_record", "robot_model"


def robot_attrs(robot) -> dict[str, Any]:
    """{robot_record: the record (absolute paths), robot_model: {path, sha256, text, meshes[, replaced]}} of a
    Robot (replaced: {link: meshes drawn as primitives}, with visual = "primitives")."""
    values = robot.record.to_toml_dict()
    values["model"] = str(robot.record.model_path)
    if robot.record.mesh_path is not None:
        values["mesh_dir"] = str(robot.record.mesh_path)
    if robot.camera_name != robot.record.camera_name:          # loaded through another camera of the model
        values["camera"] = {"name": robot.camera_name}
    source = robot.source
    model = {"path": source.path, "sha256": source.sha256, "text": source.text, "meshes": source.meshes}
    if source.replaced:                                        # visual = "primitives": what was drawn instead
        model["replaced"] = source.replaced
    return {RECORD_KEY: values, MODEL_KEY: model}


def camera_attrs(robot) -> dict[str, Any]:
    """The cameras' projections a store's ee_pixel rows are checked against (`row_checks`): the robot's own camera
    (camera_name, intrinsics, extrinsics), and each further camera's as camera_views {ee_pixel_<name>: {intrinsics,
    extrinsics}} (none: an empty dict)."""
    further = robot.projections()[1:]                          # after the robot's own ee_pixel
    return {"camera_name": robot.camera_name, "intrinsics": robot.intrinsics().tolist(),
            "extrinsics": robot.extrinsics().tolist(),
            "camera_views": {m: {"intrinsics": robot.intrinsics(m).tolist(), "extrinsics": robot.extrinsics(m).tolist()}
                             for m in further}}


def record_of_attrs(attrs: dict[str, Any]) -> tuple[RobotRecord, str | None]:
    """(record, model text) of a store's attrs; (the shipped record, None) for a store that predates them."""
    if RECORD_KEY not in attrs:
        record = load_record(str(attrs.get("robot")))
        return record, None
    model = attrs.get(MODEL_KEY) or {}
    if not isinstance(model.get("text"), str):
        raise ValueError(must_be(f"attrs[{MODEL_KEY!r}]", "the model file's text, sha256 and meshes", sorted(model),
                                 "Regenerate the store with this version of bodyschema."))
    return record_from_dict(dict(attrs[RECORD_KEY]), Path("/"), f"attrs[{RECORD_KEY!r}]"), model["text"]


def check_meshes(robot, attrs: dict[str, Any]) -> None:
    """The meshes the robot was rebuilt with must be the store's (same sha256)."""
    recorded = (attrs.get(MODEL_KEY) or {}).get("meshes") or {}
    changed = sorted(k for k, digest in recorded.items() if robot.source.meshes.get(k) != digest)
    if changed:
        raise ValueError(must_be("the robot's mesh files", "those the store was made with (same sha256)", changed,
                                 "Restore them, or regenerate the store."))
