"""`read_mjcf`: an MJCF file as a MuJoCo spec, its includes, meshes and textures found and checked first."""

from __future__ import annotations

from pathlib import Path

import mujoco

from bodyschema.datagen.body.model_files import Budget, mjcf_files, one_line, parse_xml
from bodyschema.errors import must_be


def read_mjcf(path: Path, text: str, record, budget: Budget) -> tuple[mujoco.MjSpec, dict[str, str], dict]:
    """(spec, {file as written: sha256}, {}) for the MJCF `text` read from `path`; files resolve inside its folder
    or the record's `mesh_dir` (formats.py: the reader contract)."""
    roots = [path.parent] + ([record.mesh_path] if record.mesh_path else [])
    includes, meshes = mjcf_files(parse_xml(text, path, "MJCF"), path, roots, budget)
    try:
        spec = mujoco.MjSpec.from_string(text, include=includes or None)
    except (ValueError, RuntimeError) as e:
        raise ValueError(must_be(f"the MJCF {path}", "a model MuJoCo parses", one_line(e))) from e
    spec.modelfiledir = str(path.parent)       # meshes and textures resolve as if read from the file
    return spec, meshes, {}
