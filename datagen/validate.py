"""`validate_store`: every problem of a dataset store at once (as LeRobot's `validate_frame`), and a summary.

Checks: the completion marker and per-shard markers, required attrs, each array's presence, dtype and shape,
that first axes agree, every chunk readable (Zstd checksums catch corrupted bytes), no NaN/inf, q inside the
recorded ranges, and ee_pixel equal to ee_xyz projected through the stored intrinsics and extrinsics.
Arrays are read one chunk of rows at a time, so memory stays small for image datasets.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import zarr

from bodyschema.datagen.camera import project
from bodyschema.datagen.store import DONE, REQUIRED_ATTRS, features, open_store
from bodyschema.errors import must_be

PIXEL_TOL = 0.05  # px; float32 storage of ee_xyz/ee_pixel gives ~1e-4 px, a real shift is >= 0.1 px
RANGE_TOL = 1e-5  # rad; float32 rounding of the range ends
RESUME_HINT = "Rerun the same `bodyschema datagen` command to resume it."


def _expected_features(attrs: dict) -> dict[str, dict]:
    if isinstance(attrs.get("features"), dict):
        return attrs["features"]
    dq = len(attrs.get("joint_names", [])) or int(attrs.get("dq", 0))  # best effort without the schema attr
    image = None
    if attrs.get("images") and "image_size" in attrs:
        image = (*attrs["image_size"], 3) if attrs.get("channels") == 3 else tuple(attrs["image_size"])
    return features(dq, image, False, attrs.get("sampler") == "babble")


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
    if "image" in usable and "image_size" in attrs:
        h, w = attrs["image_size"]
        if tuple(usable["image"].shape[1:3]) != (h, w):
            problems.append(must_be("image height, width", f"attrs image_size {(h, w)}", usable["image"].shape[1:3]))
    return usable


def _check_content(usable: dict[str, zarr.Array], attrs: dict, problems: list[str]) -> None:
    """Read every chunk of rows once: readability, finiteness, q ranges, pixel/xyz consistency."""
    if not usable:
        return
    n = next(iter(usable.values())).shape[0]
    step = int(attrs.get("chunk_len") or next(iter(usable.values())).chunks[0])
    ranges_key = "sampling_ranges" if attrs.get("sampler") in ("uniform", "gaussian") else "joint_limits"
    q_range = np.asarray(attrs[ranges_key], float) if ranges_key in attrs else None
    K = np.asarray(attrs["intrinsics"], float) if "intrinsics" in attrs else None
    E = np.asarray(attrs["extrinsics"], float) if "extrinsics" in attrs else None
    nonfinite = {}  # name -> [count, first row]
    q_out, pix_err, ints_bad = [0, None], [0, 0.0, None], {}
    for start in range(0, n, step):
        stop = min(n, start + step)
        block = {}
        for name, arr in usable.items():
            try:
                block[name] = np.asarray(arr[start:stop])
            except Exception as e:  # noqa: BLE001 - any decoding failure is a corrupt chunk
                problems.append(must_be(f"{name} rows {start}:{stop}", "readable", f"{type(e).__name__}: {e}",
                                        "Its chunk file is corrupt or truncated; regenerate with --overwrite."))
        for name, values in block.items():
            if values.dtype.kind == "f":
                bad = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1)
                if bad.any():
                    entry = nonfinite.setdefault(name, [0, start + int(np.argmax(bad))])
                    entry[0] += int(bad.sum())
            elif name == "episode" and (values < 0).any():
                ints_bad.setdefault(name, start + int(np.argmax(values < 0)))
        if "q" in block and q_range is not None and q_range.shape == (block["q"].shape[1], 2):
            q = block["q"]
            out = ((q < q_range[:, 0] - RANGE_TOL) | (q > q_range[:, 1] + RANGE_TOL)).any(axis=1)
            out &= np.isfinite(q).all(axis=1)  # NaN/inf are reported once, as not finite
            if out.any():
                q_out[0] += int(out.sum())
                q_out[1] = q_out[1] if q_out[1] is not None else start + int(np.argmax(out))
        if "ee_xyz" in block and "ee_pixel" in block and K is not None and E is not None:
            with np.errstate(all="ignore"):
                err = np.abs(project(K, E, block["ee_xyz"].astype(float)) - block["ee_pixel"]).max(axis=1)
            finite = np.isfinite(block["ee_xyz"]).all(axis=1) & np.isfinite(block["ee_pixel"]).all(axis=1)
            bad = ~(err <= PIXEL_TOL) & finite  # NaN/inf rows are reported once, as not finite
            if bad.any():
                pix_err[0] += int(bad.sum())
                pix_err[1] = max(pix_err[1], float(np.nanmax(np.where(bad, err, 0.0))))
                pix_err[2] = pix_err[2] if pix_err[2] is not None else start + int(np.argmax(bad))
    for name, (count, row) in nonfinite.items():
        problems.append(must_be(f"{name}", "finite", f"{count} rows with NaN/inf, first at row {row}",
                                "NaN marks samples never written: " + RESUME_HINT))
    for name, row in ints_bad.items():
        problems.append(must_be(f"{name}", ">= 0", f"negative values, first at row {row}", RESUME_HINT))
    if q_out[0]:
        problems.append(must_be("q", f"inside the recorded {ranges_key} (+-{RANGE_TOL} rad)",
                                f"{q_out[0]} rows outside, first at row {q_out[1]}"))
    if pix_err[0]:
        problems.append(must_be("ee_pixel", f"ee_xyz projected through attrs intrinsics/extrinsics (+-{PIXEL_TOL} px)",
                                f"{pix_err[0]} rows off by up to {pix_err[1]:.3g} px, first at row {pix_err[2]}"))


def validate_store(path: str | Path) -> list[str]:
    """Every problem found in the store at `path`; an empty list means it is valid and complete."""
    try:
        root = open_store(Path(path))
        attrs = dict(root.attrs)
    except Exception as e:  # noqa: BLE001 - an unopenable store is one problem, reported, not raised
        return [str(e)]
    problems: list[str] = []
    missing = [key for key in REQUIRED_ATTRS if key not in attrs]
    if missing:
        problems.append(must_be("root attrs", "complete", f"missing {missing}", "Regenerate the store."))
    if attrs.get("complete") is not True:
        problems.append(must_be("store", "complete (attr complete=True, written last)", "no completion marker",
                                RESUME_HINT))
    if DONE in root.array_keys():
        try:
            done = np.asarray(root[DONE][:]).astype(bool)
            if not done.all():
                problems.append(must_be("every shard", "done", f"shards {np.flatnonzero(~done).tolist()[:20]} not done",
                                        RESUME_HINT))
        except Exception as e:  # noqa: BLE001
            problems.append(f"{DONE} is unreadable: {type(e).__name__}: {e}.")
    usable = _check_layout(root, attrs, problems)
    _check_content(usable, attrs, problems)
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
        xyz = np.asarray(root["ee_xyz"][:])
        lo, hi = np.nanmin(xyz, axis=0), np.nanmax(xyz, axis=0)
        lines.append("  ee_xyz box (m): " + ", ".join(f"{c} [{l:+.3f}, {h:+.3f}]" for c, l, h in zip("xyz", lo, hi)))
    size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    lines.append(f"  on disk: {size / 1e6:.2f} MB · versions {a.get('versions')}")
    if check:
        problems = validate_store(path)
        lines.append("  valid" if not problems else f"  {len(problems)} problems:\n    - " + "\n    - ".join(problems))
    return "\n".join(lines)
