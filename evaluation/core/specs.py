"""Model specs and the benchmark robot: `--model SPEC` → SensoryModel, with what it resolved to (provenance), and
the robot the models are of, with the camera and joint box they were trained for.

Specs: "analytic:<robot>:<modality>" (<robot>: a shipped name or an MJCF/URDF/record path), "models:/<name>@<alias>"
or "models:/<name>/<version>" (the registry: the alias is resolved once and the version it named is what loads and
what is recorded), a model directory logged by `bodyschema train` (its digest must be recorded in the tracking
database) or "trusted:<dir>" (loaded unchecked). The robot of the models is their body's (`models.body_robot`).
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import numpy as np

from bodyschema.base import modalities
from bodyschema.cli_marks import Flag
from bodyschema.errors import must_be

MODELS_HELP = ('"models:/<name>@<alias>" (registry), a saved model directory, or "analytic:<robot>:<modality>"; '
               'several models of one body are fused')
PROVENANCE_KEYS = ("spec", "name", "version", "run_id", "sha256")
_log = logging.getLogger(__name__)
_REGISTRY = re.compile(r"^models:/(?P<name>[^/@]+)(?:@(?P<alias>[^/@]+)|/(?P<version>\d+))$")


def models_field(when_empty: str):
    """The `models` field of a benchmark config: `--model SPEC`, repeated to fuse several models (a flag that takes
    one value each time, so a second --model never silently replaces the first); none given: `when_empty`."""
    return Annotated[tuple[str, ...],
                     Flag(append=True, aliases=("--model",), help=f"{MODELS_HELP}. None given: {when_empty}")]


def resolve_models(specs: Sequence[str], when_empty: Sequence[str], tracking_uri: str | None = None,
                   models: Sequence | None = None) -> list:
    """The models of a benchmark run: `models` when given as objects, else the specs (or `when_empty`) resolved.
    Each model carries `provenance` (PROVENANCE_KEYS → str): what its spec resolved to. A model resolved before
    (a sweep passes its resolved models to each case) keeps its provenance; a bare object is named by
    `object_provenance`."""
    from bodyschema.evaluation.core.runs import note_start
    note_start()                              # a benchmark starts here: its MLflow run's start time (runs.py)
    if models is not None:
        for m in models:
            if not getattr(m, "provenance", None):
                _attach(m, object_provenance(m))
        return list(models)
    return [_resolved(spec, tracking_uri) for spec in (specs or when_empty)]


def _resolved(spec: str, tracking_uri: str | None):
    start = time.perf_counter()
    model = resolve_model(spec, tracking_uri)
    _log.debug("model %s: %s %s of %s, %s (%.2f s)", spec, getattr(model, "kind", type(model).__name__),
               model.modality, model.body.robot, model.provenance, time.perf_counter() - start)
    return model


def resolve_model(spec: str, tracking_uri: str | None = None):
    """"analytic:<robot>:<modality>" | "models:/…" (registry at `tracking_uri`) | a model directory → SensoryModel.

    A model directory loads only when its digest is recorded in the tracking database (`registry.load_local`);
    "trusted:<dir>" loads one unchecked, by the user's explicit choice (tensors only: no code runs either way)."""
    if spec.startswith("analytic:"):
        parts = spec.split(":")
        if len(parts) != 3:
            raise ValueError(must_be("model spec", "'analytic:<robot>:<modality>'", spec))
        from bodyschema.models.analytic import AnalyticModel
        return _attach(AnalyticModel(parts[1], parts[2]), {"spec": spec, "name": spec, "sha256": "no weights"})
    if spec.startswith("models:/"):
        return _registered(spec, tracking_uri)
    if spec.startswith("trusted:") and Path(spec[len("trusted:"):]).is_dir():
        from bodyschema.models import load_model
        from bodyschema.training.digest import directory_sha256
        folder = spec[len("trusted:"):]
        return _attach(load_model(folder), {"spec": spec, "name": folder, "sha256": directory_sha256(folder)})
    if Path(spec).is_dir():
        from bodyschema.training.digest import directory_sha256
        from bodyschema.training.registry import load_local
        return _attach(load_local(spec, tracking=tracking_uri), {"spec": spec, "name": spec,
                                                                 "sha256": directory_sha256(spec)})
    raise ValueError(must_be("model spec", "'analytic:<robot>:<modality>', 'models:/<name>@<alias>', a model "
                             "directory logged by `bodyschema train` or 'trusted:<model directory>'", spec))


def _registered(spec: str, tracking_uri: str | None):
    """A registry spec: an alias resolved to its version once, that version loaded (digest-checked) and recorded."""
    from mlflow.exceptions import MlflowException

    from bodyschema.training.digest import DIGEST_TAG
    from bodyschema.training.registry import load, use_tracking
    match = _REGISTRY.match(spec)
    if match is None:
        return load(spec, tracking=tracking_uri)                  # its house error: not a registry URI
    client = use_tracking(tracking_uri)
    try:
        version = (client.get_model_version_by_alias(match["name"], match["alias"]) if match["alias"]
                   else client.get_model_version(match["name"], match["version"]))
    except MlflowException:
        return load(spec, tracking=tracking_uri)                  # its house error: not a registered version
    model = load(f"models:/{match['name']}/{version.version}", tracking=tracking_uri)
    return _attach(model, {"spec": spec, "name": match["name"], "version": str(version.version),
                           "run_id": version.run_id or "", "sha256": version.tags.get(DIGEST_TAG, "")})


def object_provenance(model) -> dict[str, str]:
    """What a model passed as an object (the Python API) is known by: an analytic model by the spec that builds it
    again (`analytic:<robot>:<modality>`), any other by its kind, body and modality (it has no spec)."""
    from bodyschema.models.analytic import AnalyticModel
    if isinstance(model, AnalyticModel):
        spec = f"analytic:{model.body.robot}:{model.modality}"
        return {"spec": spec, "name": spec, "sha256": "no weights"}
    kind = getattr(model, "kind", type(model).__name__)
    return {"spec": f"<{kind} object of {model.body.robot} {model.modality}>", "name": kind}


def spec_label(provenance: dict[str, str]) -> str:
    """A spec as a reader wants it: a registry alias with the version it resolved to (`models:/<name>@champion
    v3`), any other spec as given."""
    spec, version = provenance.get("spec", "?"), provenance.get("version")
    return f"{spec} v{version}" if version and "@" in spec else spec


def _attach(model, provenance: dict[str, str]):
    model.provenance = {k: str(provenance.get(k, "")) for k in PROVENANCE_KEYS}
    return model


def provenance_rows(models: Sequence) -> list[dict[str, str]]:
    """One row per model: its spec, registered name, version, source run id and weights digest, and modality."""
    return [{**getattr(m, "provenance", {"spec": "?"}), "modality": m.modality} for m in models]


# ---- the robot of the models ------------------------------------------------------------------------------
def load_robot(models: Sequence, image_size: tuple[int, int] | None = None, actuators: str = "position"):
    """The benchmark robot of the models (a shipped one by name, one from a file from the record and model text its
    models carry: `models.body_robot`), with the camera the image model (if any) was trained for, its sampling
    ranges the joint box every model was trained on."""
    from bodyschema.models.body_robot import body_robot
    image = next((m for m in models if modalities.is_image(m.modality)), None)
    rgb = False
    if image is not None:
        image_size = image_size or tuple(image.output_shape[:2])
        rgb = len(image.output_shape) == 3 and image.output_shape[2] == 3
    pixel = next((m for m in models if getattr(m, "image_size", None)), None)
    if image_size is None and pixel is not None:
        image_size = tuple(pixel.image_size)
    robot = body_robot(models[0].body, image_size=image_size, rgb=rgb, actuators=actuators)
    check_models_match(models, robot)
    robot.sampling_ranges = trained_workspace(models, robot)
    return robot


def trained_workspace(models: Sequence, robot) -> np.ndarray:
    """The joint box every model was trained on (their latent scaling ranges, intersected, inside the joint
    limits): evaluation poses come from there, not from poses a model never saw. # (Dq, 2) rad"""
    low = np.max([m.body.q_low for m in models], axis=0)
    high = np.min([m.body.q_high for m in models], axis=0)
    low, high = np.maximum(low, robot.joint_limits[:, 0]), np.minimum(high, robot.joint_limits[:, 1])
    if (high <= low).any():
        raise ValueError(must_be("the models' joint ranges", "overlapping", [list(m.body.q_low) for m in models],
                                 "Evaluate together only models trained on overlapping workspaces."))
    return np.stack([low, high], axis=1)


def check_models_match(models: Sequence, robot) -> None:
    """Every model must be over the benchmark robot and its joints, in order; a model that carries its robot's
    model file (a robot from a file) over the same file (sha256): two arms of one name are not one body."""
    from bodyschema.models.body_robot import source_sha256
    known = getattr(robot, "mjcf_sha256", None)                 # a recorded store's body may not know its file
    for m in models:
        if (m.body.robot, tuple(m.body.joint_names)) != (robot.name, tuple(robot.joint_names)):
            raise ValueError(must_be(f"{m.modality} model body", f"robot {robot.name!r} with joints "
                                     f"{list(robot.joint_names)}", f"robot {m.body.robot!r} with joints "
                                     f"{list(m.body.joint_names)}", "Evaluate models of the benchmark's robot."))
        if known is not None and source_sha256(m.body) not in (None, known):
            raise ValueError(must_be(f"{m.modality} model's robot file", f"the benchmark robot's (sha256 "
                                     f"{known[:12]}…)", f"sha256 {source_sha256(m.body)[:12]}…",
                                     f"Evaluate together only models of the same {robot.name!r} model file."))


def robot_name(ref: str) -> str:
    """The name a robot reference (a shipped name, an MJCF/URDF/record path) gives its models' bodies."""
    from bodyschema.datagen.body.infer import robot_record
    return robot_record(ref).name


def body_and_senses(models: Sequence, robot_ref: str, visual_kinds: Sequence[str], hint: str = "",
                    actuators: str = "position"):
    """(robot, [joints model, *visual models]) for benchmarks that set proprioception against vision: every model of
    `robot_ref` (a shipped name or a model/record file), at least one visual model of `visual_kinds`; the robot's
    exact joints model is added when none is given, and the sampling box is the one every model was trained on (the
    added joints model's too)."""
    from bodyschema.models.analytic import AnalyticModel
    name = robot_name(robot_ref)
    for m in models:
        if m.body.robot != name:
            raise ValueError(must_be(f"{m.modality} model body", f"robot {name!r}", m.body.robot,
                                     "Evaluate models of the benchmark's robot (or set --robot)."))
    visual = [m for m in models if m.modality != "joints"]
    if not visual or any(m.modality not in visual_kinds for m in visual):
        raise ValueError(must_be("model modalities", f"at least one of {tuple(visual_kinds)} (plus optionally "
                                 "joints)", [m.modality for m in models], hint))
    robot = load_robot(models, actuators=actuators)
    proprio = next((m for m in models if m.modality == "joints"), None) or AnalyticModel(models[0].body, "joints")
    robot.sampling_ranges = trained_workspace([proprio, *visual], robot)
    return robot, [proprio, *visual]


def resolve_encoder(spec: str | None, robot, tracking_uri: str | None = None):
    """The image encoder of `spec` (None: none), checked against the benchmark robot and its camera image."""
    if spec is None:
        return None
    encoder = resolve_model(spec, tracking_uri)
    if not getattr(encoder, "encodes", False):
        raise ValueError(must_be("encoder", "a model of kind 'encoder' (bodyschema train encoder)",
                                 getattr(encoder, "kind", type(encoder).__name__)))
    check_models_match([encoder], robot)
    want = (*robot.image_size, *((3,) if robot.channels == 3 else ()))
    if tuple(encoder.image_shape) != want:
        raise ValueError(must_be("encoder image shape", f"the benchmark camera's {want}", encoder.image_shape,
                                 "Train the encoder on images of the same camera and size as the decoder."))
    return encoder


def on_device(models: Sequence, device: str) -> None:
    """Move every network to `device` (checked: the house error when CUDA is asked for but absent)."""
    from bodyschema.models.device import check_device
    target = check_device(device)
    for m in models:
        if hasattr(m, "to"):
            m.to(target)
