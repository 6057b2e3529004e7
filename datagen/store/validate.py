"""`validate_store`: every problem of a dataset store at once (as LeRobot's `validate_frame`), and a summary.

Checks, all reported together:
- completeness: the completion marker, every shard's done marker, every expected chunk file of every array on disk
  (Zarr would read a missing chunk as fill values: zeros for images) and, per done shard, the checksum in its
  marker equal to the one of its rows as stored now (`integrity`);
- layout: required attrs, each array's presence, dtype (image uint8, ...) and shape, first axes agreeing;
- attrs: robot a shipped name or a plain identifier (no path), joint_names/joint_limits/sampling_ranges of q's
  width (limits finite, lo <= hi); for a shipped robot, its joint count, joint names, joint limits and MJCF sha256;
- content, per chunk of rows: readable (Zstd checksums catch corrupted bytes), finite, and physical: q inside the
  recorded ranges and the joint limits, ee_xyz within the arm's reach of its base, |each Jacobian column| <= the
  reach (m/rad), ee_pixel equal to ee_xyz projected through the stored camera, touch and t >= 0, episode >= 0,
  |qvel| <= MAX_JOINT_SPEED, the babbling targets inside the joint limits (a store made before datagen recorded
  them has no `target` and no feature of it: nothing is missing) (`row_checks`).
Arrays are read one chunk of rows at a time, so memory stays small for image datasets.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
import zarr

from bodyschema.base.modalities import images_in
from bodyschema.datagen.body.record import SHIPPED
from bodyschema.datagen.store.integrity import block_digest, data_arrays, missing_chunks
from bodyschema.datagen.store.remedies import EDITED_HINT, REPAIR_HINT, RESUME_HINT
from bodyschema.datagen.store.row_checks import RANGE_TOL, RowTally, check_rows, report_rows
from bodyschema.datagen.store.schema import DONE, REQUIRED_ATTRS, features, has_checksums, open_store
from bodyschema.errors import must_be

ROBOT_NAME = re.compile(r"[^/\\:\x00-\x1f]{1,100}")  # a name (models, runs, files use it), never a path


@functools.lru_cache(maxsize=None)
def shipped_robot(name: str) -> tuple[str, tuple[str, ...], np.ndarray]:
    """(MJCF sha256, joint names, (Dq, 2) joint limits rad) of the shipped robot `name` (compiled once per process)."""
    from bodyschema.datagen.body.robot import Robot

    robot = Robot.load(name)
    try:
        return robot.mjcf_sha256, tuple(robot.joint_names), np.array(robot.joint_limits, float)
    finally:
        robot.close()


def _box(attrs: dict, key: str, dq: int, problems: list[str]) -> np.ndarray | None:
    """attrs[key] as a (dq, 2) finite float array with lo <= hi, else a problem and None."""
    if key not in attrs:
        return None  # reported with the required attrs
    try:
        box = np.asarray(attrs[key], float)
    except (TypeError, ValueError):
        box = None
    if box is None or box.shape != (dq, 2) or not np.isfinite(box).all() or (box[:, 0] > box[:, 1]).any():
        problems.append(must_be(f"attrs {key}", f"({dq}, 2) finite (lo, hi) rad with lo <= hi, one per q column",
                                _short(attrs[key]), EDITED_HINT))
        return None
    return box


def _short(value):
    """`value` as it came, or its repr cut to 80 characters (an edited attr can be huge)."""
    text = repr(value)
    return value if len(text) <= 80 else text[:77] + "..."


def _check_attrs(attrs: dict, dq: int | None, problems: list[str]) -> np.ndarray | None:
    """The attrs' types and shapes, and their agreement with the shipped robot they name; returns the (Dq, 2) joint
    limits q must lie in (the shipped robot's, else the store's own when well-formed), or None."""
    robot, shipped = attrs.get("robot"), SHIPPED
    if "robot" in attrs and not (isinstance(robot, str) and ROBOT_NAME.fullmatch(robot) and robot not in (".", "..")):
        problems.append(must_be("attrs robot", f"one of {shipped} or a robot record's name (no '/', '\\', ':')",
                                _short(robot), EDITED_HINT))
        robot = None
    if dq is None:
        return None  # no usable q: nothing to compare the attrs with
    names = attrs.get("joint_names")
    names_ok = isinstance(names, list) and len(names) == dq and all(isinstance(n, str) for n in names)
    if "joint_names" in attrs and not names_ok:
        problems.append(must_be("attrs joint_names", f"{dq} strings (q's width)", _short(names), EDITED_HINT))
    if "dq" in attrs and attrs["dq"] != dq:
        problems.append(must_be("attrs dq", f"q's width {dq}", _short(attrs["dq"]), EDITED_HINT))
    _box(attrs, "sampling_ranges", dq, problems)
    limits = _box(attrs, "joint_limits", dq, problems)
    if robot in shipped:
        return _check_shipped(robot, attrs, dq, names_ok, limits, problems)
    return limits


def _check_shipped(robot: str, attrs: dict, dq: int, names_ok: bool, limits: np.ndarray | None,
                   problems: list[str]) -> np.ndarray | None:
    """The store's q width, joint names, limits and MJCF digest equal to those of the shipped `robot`."""
    sha, names, true_limits = shipped_robot(robot)
    if dq != len(names):
        problems.append(must_be("q's width", f"{robot}'s joint count {len(names)}", dq, EDITED_HINT))
        return None
    if names_ok and attrs["joint_names"] != list(names):
        problems.append(must_be("attrs joint_names", f"{robot}'s {list(names)}", _short(attrs.get("joint_names")),
                                EDITED_HINT))
    if limits is not None and not np.allclose(limits, true_limits, rtol=0, atol=RANGE_TOL):
        problems.append(must_be("attrs joint_limits", f"{robot}'s {true_limits.tolist()}", _short(limits.tolist()),
                                EDITED_HINT))
    recorded = attrs.get("mjcf_sha256")
    if recorded is not None and recorded != sha:
        problems.append(must_be("attrs mjcf_sha256", f"the shipped {robot}'s {sha}", _short(recorded),
                                "The store was made from another model file; " + EDITED_HINT))
    return true_limits


def _expected_features(attrs: dict) -> dict[str, dict]:
    if isinstance(attrs.get("features"), dict):
        return attrs["features"]
    dq = len(attrs.get("joint_names", [])) or int(attrs.get("dq", 0))  # best effort without the schema attr
    image = None
    if attrs.get("images") and "image_size" in attrs:
        image = (*attrs["image_size"], 3) if attrs.get("channels") == 3 else tuple(attrs["image_size"])
    expected = features(dq, image, (), attrs.get("sampler") == "babble")
    expected.pop("target", None)  # older babble stores lack it; one that has it lists it in attrs features
    return expected


def _check_layout(root: zarr.Group, attrs: dict, problems: list[str]) -> dict[str, zarr.Array]:
    """Presence, dtype, per-sample shape and first-axis agreement; returns the arrays fit for content checks."""
    expected = _expected_features(attrs)
    present = {name: root[name] for name in root.array_keys() if name != DONE}
    n = attrs.get("n")
    firsts = {name: arr.shape[0] for name, arr in present.items() if arr.ndim}
    if n is None and firsts:
        n = max(set(firsts.values()), key=list(firsts.values()).count)
    usable = {}
    for name, spec in expected.items():
        if name not in present:
            problems.append(must_be(f"array {name!r}", "present", "missing", "Regenerate the store."))
            continue
        arr = present[name]
        ok = True
        if str(arr.dtype) != spec["dtype"]:
            problems.append(must_be(f"{name}.dtype", spec["dtype"], str(arr.dtype)))
            ok = False
        if list(arr.shape[1:]) != list(spec["shape"]):
            problems.append(must_be(f"{name}.shape", f"(N, {', '.join(map(str, spec['shape']))})", arr.shape))
            ok = False
        if ok:
            usable[name] = arr
    bad_axes = {name: first for name, first in firsts.items() if first != n}
    if bad_axes:
        problems.append(must_be("first axis of every array", f"the sample count n={n}", bad_axes,
                                "Arrays of one store share the sample axis; regenerate the store."))
        for name in bad_axes:
            usable.pop(name, None)
    for camera in images_in(usable) if "image_size" in attrs else ():
        h, w = attrs["image_size"]
        if tuple(usable[camera].shape[1:3]) != (h, w):
            problems.append(must_be(f"{camera} height, width", f"attrs image_size {(h, w)}", usable[camera].shape[1:3]))
    return usable


def _done_digests(root: zarr.Group, n_shards, problems: list[str]) -> np.ndarray | None:
    """(n_shards,) uint64 recorded checksums (0: not done), reporting shards not done; None if unreadable."""
    if DONE not in root.array_keys():
        problems.append(must_be(DONE, "present (the per-shard checksums)", "missing: checksums missing",
                                "No shard can be checked without it: " + REPAIR_HINT))
        return None
    try:
        digests = np.asarray(root[DONE][:])
    except Exception as e:  # noqa: BLE001 — any damage to the marker chunk is reported as a problem, not raised
        problems.append(must_be(DONE, "readable", f"{type(e).__name__}: {e}",
                                "A marker chunk is damaged: " + REPAIR_HINT))
        return None
    if isinstance(n_shards, int) and digests.shape != (n_shards,):
        problems.append(must_be(f"{DONE} shape", f"({n_shards},): one checksum per shard of attrs n_shards",
                                digests.shape, "It was replaced: " + REPAIR_HINT))
        return None
    if not digests.all():
        problems.append(must_be("every shard", "done", f"shards {np.flatnonzero(digests == 0).tolist()[:20]} not done",
                                RESUME_HINT))
    if not has_checksums(root):
        problems.append(must_be(DONE, "a checksum per shard (schema 2)", f"{digests.dtype} flags (schema 1)",
                                "Its shards cannot be checked; regenerate with `bodyschema datagen --overwrite`."))
        return None
    return digests.astype(np.uint64)


def _check_content(path: Path, root: zarr.Group, usable: dict[str, zarr.Array], attrs: dict,
                   digests: np.ndarray | None, limits: np.ndarray | None, problems: list[str]) -> None:
    """Chunk files on disk, then every chunk of rows once: readable, checksum, finite and physical values."""
    if not usable:
        return
    n = next(iter(usable.values())).shape[0]
    step = int(attrs.get("chunk_len") or next(iter(usable.values())).chunks[0])
    done = digests != 0 if digests is not None else np.ones(-(-n // step), bool)
    gone = {name: [i for i in rows if i < len(done) and done[i]]
            for name, rows in missing_chunks(path, root, sorted(usable)).items()}
    skip = set()
    for name, rows in gone.items():
        if rows:
            problems.append(must_be(f"{name} chunks", "on disk for every done shard", f"{len(rows)} missing, "
                                    f"shards {rows[:20]}", "Zarr reads them as fill values: " + REPAIR_HINT))
            skip.update(rows)
    checksum = digests is not None and set(usable) == set(data_arrays(root)) | set(_expected_features(attrs))
    tally, mismatched = RowTally(), []
    for shard, start in enumerate(range(0, n, step)):
        if shard in skip:
            continue
        stop, block = min(n, start + step), {}
        for name, arr in usable.items():
            try:
                block[name] = np.asarray(arr[start:stop])
            except Exception as e:  # noqa: BLE001 - any decoding failure is a corrupt chunk
                problems.append(must_be(f"{name} rows {start}:{stop}", "readable", f"{type(e).__name__}: {e}",
                                        "Its chunk file is corrupt or truncated: " + REPAIR_HINT))
        if checksum and shard < len(digests) and digests[shard] and len(block) == len(usable):
            if block_digest(block) != int(digests[shard]):
                mismatched.append(shard)
        check_rows(block, attrs, limits, start, tally)
    if mismatched:
        problems.append(must_be("every done shard", f"equal to the checksum in its {DONE} marker",
                                f"{len(mismatched)} differ, shards {mismatched[:20]}",
                                "Its chunks changed after they were written: " + REPAIR_HINT))
    report_rows(tally, attrs, problems)


def validate_store(path: str | Path) -> list[str]:
    """Every problem found in the store at `path`; an empty list means it is valid and complete."""
    try:
        root = open_store(Path(path))
    except Exception as e:  # noqa: BLE001 - an unopenable store is one problem, reported, not raised
        return [str(e)]
    return validate_open_store(Path(path), root)


def validate_open_store(path: Path, root: zarr.Group) -> list[str]:
    """`validate_store` of the store at `path`, already opened as `root` (a reader keeps the group it checked)."""
    attrs = dict(root.attrs)
    problems: list[str] = []
    missing = [key for key in REQUIRED_ATTRS if key not in attrs]
    if missing:
        problems.append(must_be("root attrs", "complete", f"missing {missing}", "Regenerate the store."))
    if attrs.get("complete") is not True:
        problems.append(must_be("store", "complete (attr complete=True, written last)", "no completion marker",
                                RESUME_HINT))
    digests = _done_digests(root, attrs.get("n_shards"), problems)
    usable = _check_layout(root, attrs, problems)
    limits = _check_attrs(attrs, usable["q"].shape[1] if "q" in usable else None, problems)
    _check_content(Path(path), root, usable, attrs, digests, limits, problems)
    return problems


def summarize_store(path: str | Path, check: bool = True) -> str:
    """A human-readable summary: robot, sampler, arrays (shape, dtype, unit), workspace, size, validity."""
    path = Path(path)
    root = open_store(path)
    a = dict(root.attrs)
    lines = [f"{path}: {a.get('robot')} · sampler {a.get('sampler')} · n={a.get('n')} · seed {a.get('seed')} · "
             f"{'complete' if a.get('complete') else 'INCOMPLETE'}",
             f"  joints {a.get('joint_names')} · camera {a.get('camera_name')!r} {a.get('image_size')} px "
             f"x{a.get('channels')} · created {a.get('created_at')}"]
    for name in sorted(root.array_keys()):
        arr = root[name]
        lines.append(f"  {name:<10} {str(tuple(arr.shape)):<22} {str(arr.dtype):<8} {arr.attrs.get('unit', '')}")
    if "ee_xyz" in root.array_keys():
        try:
            xyz = np.asarray(root["ee_xyz"][:])
            xyz = xyz[np.isfinite(xyz).all(axis=1)]
            lo, hi = xyz.min(axis=0), xyz.max(axis=0)
            box = ", ".join(f"{c} [{low:+.3f}, {high:+.3f}]" for c, low, high in zip("xyz", lo, hi))
            lines.append(f"  ee_xyz box (m): {box}")
        except Exception as e:  # noqa: BLE001 - a damaged or empty array is listed by validate_store below
            lines.append(f"  ee_xyz box (m): unavailable ({type(e).__name__})")
    size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    lines.append(f"  on disk: {size / 1e6:.2f} MB · versions {a.get('versions')}")
    if check:
        problems = validate_open_store(path, root)
        lines.append("  valid" if not problems else f"  {len(problems)} problems:\n    - " + "\n    - ".join(problems))
    return "\n".join(lines)
