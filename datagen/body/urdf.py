"""`read_urdf` (the URDF row of formats.py): a URDF as a MuJoCo spec, its meshes found and checked first.

MuJoCo compiles URDF itself but neither resolves `package://` paths nor reads every mesh format. Each mesh path is
resolved here: `package://PKG/REST` in the folder named PKG nearest above the URDF (the ROS package holding it), then
PKG/REST or REST beside the URDF or in `mesh_dir`; a plain path against the URDF's folder, then `mesh_dir`. Nothing
resolves outside those folders (`model_files`: no absolute path elsewhere, no `..` out, no walk up to `/`). Each mesh
file is read once and goes to MuJoCo as one named asset however many links show it (no path guessing on its side).
A format MuJoCo does not load (.dae, ...) or a mesh not found is the house error naming the file, unless
`visual="collision"` asks for the collision geometry to be rendered instead of the visual meshes, or
`visual="primitives"` replaces every mesh by capsules and boxes sized from the links (`primitives`: no mesh file is
read, and the links that got primitives are returned with the meshes they lost).
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco

from bodyschema.datagen.body.model_files import MAX_ASSETS, Budget, inside, one_line, parse_xml
from bodyschema.datagen.body.primitives import add_primitives, strip_meshes
from bodyschema.errors import must_be

MESH_SUFFIXES = (".stl", ".obj", ".msh")    # what MuJoCo loads
MIN_MASS, MIN_INERTIA = 1e-4, 1e-8          # kg, kg·m²: MuJoCo's compiler raises lighter links to these


PRIMITIVES = "`bodyschema robot init FILE --visual primitives` draws capsules and boxes sized from the links instead"


def read_urdf(path: Path, text: str, record, budget: Budget) -> tuple[mujoco.MjSpec, dict[str, str], dict]:
    """The URDF row of formats.py: `load_urdf` with the record's `mesh_dir` and `visual`."""
    return load_urdf(path, text, record.mesh_path, record.visual, budget)


def load_urdf(path: Path, text: str, mesh_dir: Path | None, visual: str, budget: Budget | None = None
              ) -> tuple[mujoco.MjSpec, dict[str, str], dict[str, list[str]]]:
    """(spec, {mesh path as written in the URDF: sha256}, {link: meshes replaced by primitives}) for the URDF
    `text` read from `path`."""
    budget = budget or Budget()
    root = parse_xml(text, path, "URDF")
    if root.tag != "robot":
        raise ValueError(must_be(f"the URDF {path}", "a <robot> document", f"<{root.tag}>"))
    replaced = strip_meshes(root) if visual == "primitives" else {}
    if visual == "collision":
        for link in root.iter("link"):
            for element in link.findall("visual"):
                link.remove(element)
    assets, digests, names, references = {}, {}, {}, 0
    for kind in ("visual", "collision"):
        for element in root.iter(kind):
            for mesh in element.iter("mesh"):
                references += 1
                if references > MAX_ASSETS:
                    raise ValueError(must_be(f"the mesh references of the URDF {path}", f"at most {MAX_ASSETS}",
                                             "more", "Merge or drop meshes."))
                written = mesh.get("filename", "")
                file = resolve_mesh(written, Path(path).parent, mesh_dir, path)
                _check_format(file, written, kind)
                if file not in names:             # one asset per file, however many links show it
                    data = budget.read(file, f"{kind} mesh {written!r} of {path}")
                    names[file] = (f"mesh{len(assets)}_{file.stem}{file.suffix.lower()}",
                                   hashlib.sha256(data).hexdigest())
                    assets[names[file][0]] = data
                mesh.set("filename", names[file][0])
                digests[written] = names[file][1]
    _keep_visuals(root)
    try:
        spec = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"), assets=assets)
    except (ValueError, RuntimeError) as e:
        raise ValueError(must_be(f"the URDF {path}", "a robot MuJoCo parses", one_line(e),
                                 "Check its links and joints (one parent each, no cycles).")) from e
    add_primitives(spec, list(replaced))
    # a moving link of zero mass (common: frames, fingers written with <mass value="0"/>) would not compile
    spec.compiler.boundmass, spec.compiler.boundinertia = max(spec.compiler.boundmass, MIN_MASS), \
        max(spec.compiler.boundinertia, MIN_INERTIA)
    return spec, digests, replaced


def resolve_mesh(written: str, folder: Path, mesh_dir: Path | None, urdf: Path | str = "the URDF") -> Path:
    """The file a URDF mesh path names, inside the URDF's folder, `mesh_dir` or the package it names (house error
    listing where it was looked for, or saying which folders a path may resolve in)."""
    if written.startswith("file://"):
        written = written[len("file://"):]
    places = [] if mesh_dir is None else [Path(mesh_dir)]
    if written.startswith("package://"):
        package, _, rest = written[len("package://"):].lstrip("/").partition("/")
        # the folder named PKG nearest above the URDF (a ROS package holding it), else PKG/ or the file in a place
        above = next((p for p in [folder.resolve(), *folder.resolve().parents] if p.name == package and package), None)
        tops = [(top / package, top) for top in [*places, folder]] + [(top, top) for top in [*places, folder]]
        if above is not None:
            tops.insert(0, (above, above))
        tried = []
        for base, root in tops:
            candidate = base / rest
            tried.append(candidate)
            if candidate.is_file():
                return inside(rest, base, [root], "mesh", str(urdf))
        raise FileNotFoundError(must_be(f"mesh {written} of {urdf}", "found in a folder named "
                                        f"{package!r} above the URDF, beside it or in --mesh-dir",
                                        f"not in {[str(t) for t in tried[:4]]} ...",
                                        f"Pass --mesh-dir pointing at the folder that holds {package}/ or {rest}, "
                                        f"or {PRIMITIVES}."))
    candidates = [(folder, written), *((p, written) for p in places)]
    found = next(((base, w) for base, w in candidates if (base / w).is_file()), None)
    if found is None:
        raise FileNotFoundError(must_be(f"mesh {written} of {urdf}", "an existing file (relative to the URDF or "
                                        "--mesh-dir)", [str(b / w) for b, w in candidates],
                                        f"Pass --mesh-dir with the mesh folder, or {PRIMITIVES}."))
    return inside(found[1], found[0], [folder, *places], "mesh", str(urdf))


def _check_format(file: Path, written: str, kind: str) -> None:
    if file.suffix.lower() in MESH_SUFFIXES:
        return
    hint = "Convert it to STL or OBJ (e.g. with meshlab or trimesh) and point the URDF at the copy"
    if kind == "visual":
        hint += (", or render the collision geometry instead: `bodyschema robot init FILE --visual collision` "
                 "writes a record saying so")
    hint += f", or {PRIMITIVES}"
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
