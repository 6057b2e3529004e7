"""`import_recording(config)`: read the source, apply the body, prepare the images, add forward kinematics when
asked, and write the store (writer.py). The root attrs are a generated store's, with sampler "imported", no seed,
and `source` = {format, path, sha256 of every file read}.

Camera and reach attrs describe what the robot computes: they are recorded (and `validate_store` checks ee_pixel
against the camera, ee_xyz against the reach) when those arrays come from the robot (--fk) or from a bodyschema
export, and left None when a foreign recording brings its own ee readings, whose camera and frame are unknown.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from bodyschema.base import modalities
from bodyschema.datagen.exchange.importers.body import (
    RANGE_TOL,
    Body,
    in_body_order,
    joint_angles,
    joint_box,
    resolve_body,
)
from bodyschema.datagen.exchange.importers.config import ImportConfig
from bodyschema.datagen.exchange.importers.images import prepare_images
from bodyschema.datagen.exchange.importers.recording import EXTRA_ARRAYS, Recording, check_finite, source_sha256
from bodyschema.datagen.exchange.importers.writer import chunk_rows, store_features, write_store
from bodyschema.datagen.store.schema import SCHEMA_VERSION, now, versions
from bodyschema.errors import must_be

logger = logging.getLogger(__name__)
FK_ARRAYS = ("ee_xyz", "ee_rot", "ee_pixel", "jacobian")


def import_recording(config: ImportConfig) -> Path:
    """Import `config.source` into the store `config.out`; returns its path once complete and valid."""
    source = Path(config.source)
    if not source.exists():
        raise FileNotFoundError(must_be("SOURCE", "an existing folder, HDF5 file or LeRobot dataset", str(source)))
    rec = read_source(source, config)
    arrays: dict[str, np.ndarray] = {}
    if config.images and rec.images is not None:
        arrays["image"] = prepare_images(rec.images, rec.image_names, config.crop, config.resize, config.gray)
    image_size = tuple(arrays["image"].shape[1:3]) if "image" in arrays else None
    body = resolve_body(config, rec, image_size)
    try:
        q = joint_angles(config, rec, body)                                          # (N, Dq) rad
        arrays["q"] = q.astype(np.float32)
        arrays.update(_extras(rec, config))
        if "target" in arrays:
            _place_targets(rec, body, arrays)
        foreign = {k for k in FK_ARRAYS if k in arrays} if not rec.attrs else set()
        if config.fk:
            arrays.update(_forward_kinematics(body, q, arrays))
            foreign = set()
        attrs = _attrs(config, rec, body, arrays, source, foreign)
    finally:
        if body.robot is not None:
            body.robot.close()
    if rec.dropped:
        logger.warning("import: not imported (no place in the store): " + "; ".join(
            f"{name} ({why})" for name, why in rec.dropped.items()))
    return write_store(Path(config.out), arrays, attrs, config.overwrite, source)


def _place_targets(rec: Recording, body: Body, arrays: dict[str, np.ndarray]) -> None:
    """The recorded commands (rad, q's columns) in the body's joint order as the store's `target`; commands outside
    the joint limits (which `validate` requires of a target) are dropped, and `rec.dropped` says so."""
    target = in_body_order(rec, body, arrays["target"])                               # (N, Dq) rad
    lo, hi = body.joint_limits.T
    outside = ((target < lo - RANGE_TOL) | (target > hi + RANGE_TOL)).any(axis=1)
    if outside.any():
        del arrays["target"]
        j = int(np.nonzero((target[outside] < lo - RANGE_TOL) | (target[outside] > hi + RANGE_TOL))[1][0])
        rec.dropped["action"] = (f"commands outside the joint limits in {int(outside.sum())} rows (first: "
                                 f"{body.joint_names[j]}); a store's `target` lies inside them")
        return
    arrays["target"] = target


def read_source(source: Path, config: ImportConfig) -> Recording:
    """The recording at `source`; a file of the wrong structure that a reader's own checks missed (a key absent, a
    value of another type) is the house error naming the source, not a traceback."""
    fmt = config.format if config.format != "auto" else _detect(source)
    try:
        return _read(source, fmt, config)
    except (KeyError, TypeError, AttributeError, IndexError) as e:
        raise ValueError(must_be(f"SOURCE {source}", f"a well-formed {fmt} recording",
                                 f"{type(e).__name__}: {str(e)[:120]}", "See `bodyschema import --help` for the "
                                 "layouts read; rerun with --debug to see where it failed.")) from e


def _read(source: Path, fmt: str, config: ImportConfig) -> Recording:
    if fmt == "hdf5":
        from bodyschema.datagen.exchange.importers.hdf5 import read_hdf5
        return read_hdf5(source, config.joint_key, config.image_key, config.ee_key, config.images)
    if fmt == "lerobot":
        from bodyschema.datagen.exchange.importers.lerobot import read_lerobot
        return read_lerobot(source, config.joint_key, config.image_key, config.images)
    if not source.is_dir():
        raise ValueError(must_be("SOURCE of --format folder", "a folder of images with a CSV", str(source)))
    from bodyschema.datagen.exchange.importers.folder_csv import read_folder
    return read_folder(source, config.csv, config.images)


def _detect(source: Path) -> str:
    if source.is_file():
        if source.suffix.lower() in (".h5", ".hdf5", ".hdf"):
            return "hdf5"
        raise ValueError(must_be("SOURCE", "a folder, an .h5/.hdf5 file or a LeRobot dataset folder", str(source),
                                 "Pass --format to say which it is."))
    return "lerobot" if (source / "meta" / "info.json").is_file() else "folder"


def _extras(rec: Recording, config: ImportConfig) -> dict[str, np.ndarray]:
    """The recorded readings besides q, finite, in the store's dtypes (qvel and target converted like the angles);
    `episode` whole numbers in [0, 2^31), `t` and `touch` >= 0, ee readings of the schema's width."""
    out = {}
    where = f"{name_of(rec, config)}"
    for name, values in rec.arrays.items():
        values = np.asarray(values)
        if values.dtype.kind not in "biuf":
            raise ValueError(must_be(f"{name} in {where}", "numbers", f"dtype {values.dtype}"))
        if name in ("qvel", "target") and config.angles == "deg":   # joint velocities and angles, as q
            values = values * config.to_rad
        if values.dtype.kind == "f":
            check_finite(f"{name} in {where}", values, rec.image_names or None)
        _check_range(name, values, where, rec.image_names)
        out[name] = values.astype(EXTRA_ARRAYS[name])
    return out


EPISODE_MAX = 2 ** 31 - 1        # the store keeps episode as int32
# per-frame shape (None: any); the kinematic arrays' from the modality table
WIDTHS = {**{m: modalities.get(m).shape for m in ("ee_xyz", "ee_rot", modalities.EE_PIXEL)},
          "touch": None, "episode": (), "t": ()}


def name_of(rec: Recording, config: ImportConfig) -> str:
    """The file the readings came from, for messages: the CSV of a folder, else the source."""
    return rec.params.get("csv") or Path(config.source).name


def _check_range(name: str, values: np.ndarray, where: str, labels: list[str]) -> None:
    """What the store's schema (and validate) require of a recorded reading, said about the recording."""
    def at(bad: np.ndarray) -> str:
        row = int(np.flatnonzero(bad)[0])
        return labels[row] if labels else f"row {row + 1}"

    width = WIDTHS.get(name)
    if width is not None and values.shape[1:] != width:
        raise ValueError(must_be(f"{name} in {where}", f"one value per frame of shape {width}",
                                 f"shape {values.shape[1:]} per frame"))
    flat = values.reshape(len(values), -1)
    if name == "episode":
        bad = (flat != np.round(flat)).any(axis=1) | (flat < 0).any(axis=1) | (flat > EPISODE_MAX).any(axis=1)
        if bad.any():
            raise ValueError(must_be(f"episode in {where}", f"a whole number in [0, {EPISODE_MAX}]",
                                     f"{flat[bad][0].item()!r} at {at(bad)}", "Number the episodes 0, 1, 2, ..."))
    if name == "ee_rot":
        _check_rotations(flat, where, at)
    if name in ("t", "touch"):
        bad = (flat < 0).any(axis=1)
        if bad.any():
            unit = "time (s) since the recording began" if name == "t" else "contact reading"
            raise ValueError(must_be(f"{name} in {where}", f">= 0: a {unit}", f"{flat[bad].min().item()!r} at "
                                     f"{at(bad)} ({int(bad.sum())} rows)", "Shift or repair the column."))


ROTATION_TOL = 1e-3    # |RᵀR − I|, |det R − 1|: float32 rotations are within 1e-6, a recording rounded to 4 digits 1e-4


def _check_rotations(flat: np.ndarray, where: str, at) -> None:
    """ee_rot rows (N, 9) must be rotation matrices read row by row: orthonormal, determinant +1."""
    rot = flat.reshape(-1, 3, 3).astype(np.float64)
    off = np.abs(rot @ rot.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
    bad = (off > ROTATION_TOL) | (np.abs(np.linalg.det(rot) - 1.0) > ROTATION_TOL)
    if bad.any():
        raise ValueError(must_be(f"ee_rot in {where}", f"rotation matrices read row by row (RᵀR = I and det R = 1, "
                                 f"±{ROTATION_TOL})", f"|RᵀR − I| = {off[bad][0]:.3g} at {at(bad)} "
                                 f"({int(bad.sum())} rows)", "Convert quaternions or angles to the matrix, or "
                                 "drop the column and import with --fk."))


def _forward_kinematics(body: Body, q: np.ndarray, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """ee_xyz (N, 3) m, ee_rot (N, 9), ee_pixel (N, 2) px and jacobian (N, 3, Dq) m/rad of the robot at the
    recorded q."""
    observed = body.robot.observe(q, image=False)
    replaced = [k for k in FK_ARRAYS if k in arrays]
    if "ee_xyz" in replaced:
        gap = np.linalg.norm(arrays["ee_xyz"] - observed["ee_xyz"], axis=1).max()
        logger.warning(f"import --fk: the recorded {replaced} are replaced by the robot's (recorded ee_xyz up to "
                       f"{1e3 * gap:.1f} mm from the robot's forward kinematics)")
    return {k: observed[k] for k in FK_ARRAYS}


def _attrs(config: ImportConfig, rec: Recording, body: Body, arrays: dict, source: Path, foreign: set) -> dict:
    n, step = len(arrays["q"]), chunk_rows(arrays)
    feats = store_features(arrays)
    robot_made = dict(body.attrs)
    if "ee_pixel" in foreign:
        robot_made.update(intrinsics=None, extrinsics=None)
    if "ee_xyz" in foreign or "jacobian" in foreign:
        robot_made.update(reach_m=None, base_m=None)
    image = arrays.get("image")
    root = source if source.is_dir() else source.parent
    return {"schema_version": SCHEMA_VERSION, "robot": body.name, "dq": len(body.joint_names),
            "joint_names": list(body.joint_names), "joint_limits": body.joint_limits.tolist(),
            "sampling_ranges": joint_box(arrays["q"].astype(np.float64), body).tolist(), "workspace": None,
            **robot_made, "image_size": None if image is None else list(image.shape[1:3]),
            "channels": None if image is None else (3 if image.ndim == 4 else 1), "images": image is not None,
            "sampler": "imported", "sampler_params": rec.params, "seed": None, "config": config.to_dict(),
            "versions": versions(), "created_at": now(), "n": n, "chunk_len": step, "n_shards": -(-n // step),
            "features": feats,
            "source": {"format": rec.params.get("format"), "path": str(source.resolve()), "files": len(rec.files),
                       "sha256": source_sha256(rec.files, root), "not_imported": dict(rec.dropped)},
            "recorded_attrs": rec.attrs or None}
