"""`load_urdf`: a URDF as a MuJoCo spec, its meshes found and checked first.

MuJoCo compiles URDF itself but neither resolves `package://` paths nor reads every mesh format. Each mesh path is
resolved here: `package://PKG/REST` against the URDF's folder and its ancestors (a folder named PKG, or one holding
PKG/REST) and against `mesh_dir`; a plain path against the URDF's folder, then `mesh_dir`. Meshes go to MuJoCo as
named assets (no path guessing on its side). A format MuJoCo does not load (.dae, ...) is the house error naming
the file, unless `visual="collision"` asks for the collision geometry to be rendered instead of the visual meshes.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco

from bodyschema.errors import must_be

MESH_SUFFIXES = (".stl", ".obj", ".msh")    # what MuJoCo loads


def load_urdf(path: Path, text: str, mesh_dir: Path | None, visual: str) -> tuple[mujoco.MjSpec, dict[str, str]]:
    """(spec, {mesh path as written in the URDF: sha256}) for the URDF `text` read from `path`."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise ValueError(must_be(f"the URDF {path}", "well-formed XML", str(e))) from e
    if root.tag != "robot":
        raise ValueError(must_be(f"the URDF {path}", "a <robot> document", f"<{root.tag}>"))
    if visual == "collision":
        for link in root.iter("link"):
            for element in link.findall("visual"):
                link.remove(element)
    assets, digests = {}, {}
    for kind in ("visual", "collision"):
        for element in root.iter(kind):
            for mesh in element.iter("mesh"):
                written = mesh.get("filename", "")
                file = resolve_mesh(written, Path(path).parent, mesh_dir)
                _check_format(file, written, kind)
                data = file.read_bytes()
                name = f"mesh{len(assets)}_{file.stem}{file.suffix.lower()}"
                mesh.set("filename", name)
                assets[name], digests[written] = data, hashlib.sha256(data).hexdigest()
    _keep_visuals(root)
    return mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"), assets=assets), digests


def resolve_mesh(written: str, folder: Path, mesh_dir: Path | None) -> Path:
    """The file a URDF mesh path names (house error listing where it was looked for)."""
    if written.startswith("file://"):
        written = written[len("file://"):]
    places = [] if mesh_dir is None else [Path(mesh_dir)]
    if written.startswith("package://"):
        package, _, rest = written[len("package://"):].lstrip("/").partition("/")
        tried = []
        for top in [*places, folder, *folder.resolve().parents]:
            candidates = [top / package / rest, top / rest] if top.name != package else [top / rest]
            tried += candidates
            found = next((c for c in candidates if c.is_file()), None)
            if found:
                return found
        raise FileNotFoundError(must_be(f"mesh {written}", "found beside the URDF or in --mesh-dir",
                                        f"not in {[str(t) for t in tried[:4]]} ...",
                                        f"Pass --mesh-dir pointing at the folder that holds {package}/ or {rest}."))
    candidates = [Path(written)] if Path(written).is_absolute() else [folder / written, *(p / written for p in places)]
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        raise FileNotFoundError(must_be(f"mesh {written}", "an existing file (relative to the URDF or --mesh-dir)",
                                        [str(c) for c in candidates], "Pass --mesh-dir with the mesh folder."))
    return found


def _check_format(file: Path, written: str, kind: str) -> None:
    if file.suffix.lower() in MESH_SUFFIXES:
        return
    hint = "Convert it to STL or OBJ (e.g. with meshlab or trimesh) and point the URDF at the copy"
    if kind == "visual":
        hint += (", or render the collision geometry instead: `bodyschema robot init FILE --visual collision` "
                 "writes a record saying so")
    raise ValueError(must_be(f"{kind} mesh {written}", f"a format MuJoCo loads {MESH_SUFFIXES}", file.suffix,
                             hint + "."))


def _keep_visuals(root: ET.Element) -> None:
    """MuJoCo drops a URDF's visual geoms unless told (compiler discardvisual); keep them: they are what the
    camera should see. Appends to the URDF's own <mujoco> extension when it has one."""
    ext = root.find("mujoco")
    if ext is None:
        ext = ET.SubElement(root, "mujoco")
    compiler = ext.find("compiler")
    if compiler is None:
        compiler = ET.SubElement(ext, "compiler")
    compiler.set("discardvisual", "false")
