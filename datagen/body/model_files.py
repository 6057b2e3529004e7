"""Robot model files read under one policy, before MuJoCo sees any of them (README "Your own robot").

- Where: a model file's includes, meshes and textures resolve only inside the model file's folder or the record's
  `mesh_dir` (URDF `package://PKG/...`: also the nearest folder named PKG above the URDF); an absolute path or a `..`
  that leaves those folders is refused, and so is a symbolic link that points out of them.
- What: regular files only (a FIFO, a device such as /dev/zero, a directory is refused without being opened), each
  at most MAX_FILE_BYTES and all of one robot's files together at most MAX_TOTAL_BYTES, read once each.
- How big: at most MAX_ASSETS mesh/texture/height-field/skin elements (URDF: mesh references), textures (builtin or
  PNG) at most MAX_TEXTURE_SIDE px a side, the offscreen buffer at most MAX_OFFSCREEN px a side, the timestep inside
  TIMESTEP_RANGE; all checked on the XML and the parsed spec, before MuJoCo compiles (allocates) anything.
- XML with a DOCTYPE or entity declarations is refused (entity expansion is how a small file grows huge).
Every refusal is the house line naming the file (and, for an include or a mesh, the file that names it).
"""

from __future__ import annotations

import os
import stat
import xml.etree.ElementTree as ET
from pathlib import Path
from xml.parsers import expat

from bodyschema.errors import must_be

MAX_FILE_BYTES = 64 * 2**20      # one model, include, mesh or texture file (the largest shipped/foreign mesh: ~2 MB)
MAX_TOTAL_BYTES = 256 * 2**20    # every file of one robot together
MAX_INCLUDES = 100               # include elements, nested ones counted
MAX_ASSETS = 1000                # mesh, texture, hfield and skin elements of an MJCF; mesh references of a URDF
MAX_TEXTURE_SIDE = 4096          # px, a texture's width and height (builtin or PNG); 4096² RGB is 48 MB
MAX_OFFSCREEN = 4096             # px, <visual><global offwidth/offheight>: the render buffer is allocated that big
TIMESTEP_RANGE = (1e-4, 0.1)     # s; 1e-8 made datagen's settling step loop run for hours
ASSET_TAGS = ("mesh", "texture", "hfield", "skin")
_PNG = b"\x89PNG\r\n\x1a\n"


class Budget:
    """The bytes read so far for one robot, each file read once (same resolved path → same bytes)."""

    def __init__(self):
        self.total = 0
        self.files: dict[Path, bytes] = {}

    def read(self, path: Path, what: str) -> bytes:
        path = Path(path)
        if path in self.files:
            return self.files[path]
        data = read_regular(path, what, MAX_FILE_BYTES)
        self.total += len(data)
        if self.total > MAX_TOTAL_BYTES:
            raise ValueError(must_be(f"the files of {what}", f"at most {_size(MAX_TOTAL_BYTES)} together",
                                     f"{_size(self.total)} after {path}",
                                     "Use decimated meshes (fewer triangles) or fewer of them."))
        self.files[path] = data
        return data


def read_regular(path: Path, what: str, limit: int) -> bytes:
    """The bytes of `path`, a regular file of at most `limit` bytes; never blocks on a FIFO nor reads a device."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError as e:
        raise FileNotFoundError(must_be(what, "an existing file", str(path), "Check the path in the file that names "
                                        "it (relative to that file's folder).")) from e
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ValueError(must_be(what, "a regular file", f"{path} ({_kind(info.st_mode)})",
                                     "Point it at a file, not a device, FIFO or folder."))
        if info.st_size > limit:
            raise ValueError(must_be(what, f"a file of at most {_size(limit)}", f"{_size(info.st_size)} ({path})",
                                     "Use a smaller (decimated) file."))
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1)
        if len(data) > limit:             # grew while read
            raise ValueError(must_be(what, f"a file of at most {_size(limit)}", str(path)))
        return data
    finally:
        os.close(fd)


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n} bytes"


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def inside(written: str, base: Path, roots: list[Path], what: str, named_by: str) -> Path:
    """`written` resolved against `base`, refused unless it lies inside one of `roots` (links followed)."""
    target = (base / written).resolve()
    if not any(target.is_relative_to(root.resolve()) for root in roots):
        raise ValueError(must_be(f"{what} {written!r} named by {named_by}",
                                 f"inside {' or '.join(str(r.resolve()) for r in roots)}", str(target),
                                 "Robot files resolve only inside the model file's folder, the record's mesh_dir "
                                 "(--mesh-dir) and URDF packages found above the file; copy the file there."))
    return target


def decode(raw: bytes, path: Path | str) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(must_be(f"the model file {path}", "UTF-8 text (MJCF or URDF XML)",
                                 f"byte {raw[e.start:e.start + 1]!r} at offset {e.start}",
                                 "Save it as UTF-8, or pass the right file.")) from e


def parse_xml(text: str, path: Path | str, kind: str) -> ET.Element:
    """The XML root of `text`; a DOCTYPE or an entity declaration is refused (no expansion ever happens)."""
    def refuse(*_):
        raise ValueError(must_be(f"the {kind} {path}", "XML without a DOCTYPE or entity declarations",
                                 "a <!DOCTYPE>/<!ENTITY>", "Remove the declaration; robot files need none."))
    scan = expat.ParserCreate()                   # a first pass that only looks for declarations
    scan.StartDoctypeDeclHandler = scan.EntityDeclHandler = refuse
    try:
        scan.Parse(text, True)
        return ET.fromstring(text)
    except (expat.ExpatError, ET.ParseError) as e:
        raise ValueError(must_be(f"the {kind} {path}", "well-formed XML", str(e))) from e


def one_line(text: str) -> str:
    """A (multi-line) MuJoCo message as one line."""
    return " ".join(str(text).split()) or "no message"


def check_png(data: bytes, what: str) -> None:
    """A PNG texture's size from its header (decoded, it would take width·height·4 bytes)."""
    if data[:8] == _PNG and len(data) >= 24:
        width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
        if max(width, height) > MAX_TEXTURE_SIDE:
            raise ValueError(must_be(what, f"at most {MAX_TEXTURE_SIDE} px a side", f"{width} x {height} px",
                                     "Scale the image down."))


def check_spec(spec, path: Path | str) -> None:
    """Sizes MuJoCo would allocate at compile or render time, and the timestep, checked on the parsed spec."""
    if len(spec.meshes) + len(spec.textures) + len(spec.hfields) + len(spec.skins) > MAX_ASSETS:
        raise ValueError(must_be(f"the assets of {path}", f"at most {MAX_ASSETS} meshes, textures, height fields "
                                 "and skins", len(spec.meshes) + len(spec.textures) + len(spec.hfields) +
                                 len(spec.skins), "Merge or drop meshes."))
    for texture in spec.textures:
        if max(int(texture.width), int(texture.height)) > MAX_TEXTURE_SIDE:
            raise ValueError(must_be(f"texture {texture.name or texture.file!r} of {path}",
                                     f"at most {MAX_TEXTURE_SIDE} px a side (width, height)",
                                     f"{texture.width} x {texture.height}", "Lower width/height: a checker needs few."))
    glob = spec.visual.global_
    if max(int(glob.offwidth), int(glob.offheight)) > MAX_OFFSCREEN:
        raise ValueError(must_be(f"<visual><global offwidth/offheight> of {path}", f"at most {MAX_OFFSCREEN} px",
                                 f"{glob.offwidth} x {glob.offheight}",
                                 "Remove them: the robot's images set the buffer they need."))
    lo, hi = TIMESTEP_RANGE
    timestep = float(spec.option.timestep)
    if not lo <= timestep <= hi:
        raise ValueError(must_be(f"<option timestep> of {path}", f"in [{lo:g}, {hi:g}] s", timestep,
                                 "MuJoCo's default is 0.002 s; the shipped arms use it."))


def mjcf_files(root: ET.Element, path: Path, roots: list[Path], budget: Budget) -> tuple[dict[str, bytes], dict]:
    """({include as written: bytes}, {asset file as written: sha256}) of the MJCF `root` read from `path`: every
    include (nested ones too) and every asset file checked and read once, under the policy above."""
    import hashlib

    folder = path.parent
    includes: dict[str, bytes] = {}
    trees = [(root, path)]
    pending = [(root, path)]
    while pending:
        tree, named_by = pending.pop()
        for element in tree.iter("include"):
            written = element.get("file", "")
            if written in includes:
                continue
            if len(includes) >= MAX_INCLUDES:
                raise ValueError(must_be(f"the includes of {path}", f"at most {MAX_INCLUDES}", "more"))
            what = f"include {written!r} of {named_by}"
            file = inside(written, folder, roots, "include", str(named_by))
            includes[written] = budget.read(file, what)
            child = parse_xml(decode(includes[written], file), file, "MJCF include")
            trees.append((child, file))
            pending.append((child, file))
    compiler = {k: v for tree, _ in trees for c in tree.iter("compiler") for k, v in c.attrib.items()}
    asset_dir = compiler.get("assetdir", "")
    dirs = {"mesh": compiler.get("meshdir", asset_dir), "hfield": compiler.get("meshdir", asset_dir),
            "skin": compiler.get("meshdir", asset_dir), "texture": compiler.get("texturedir", asset_dir)}
    count, digests = 0, {}
    for tree, named_by in trees:
        for element in tree.iter():
            if element.tag in ASSET_TAGS:
                count += 1
                if count > MAX_ASSETS:
                    raise ValueError(must_be(f"the assets of {path}", f"at most {MAX_ASSETS} meshes, textures, "
                                             "height fields and skins", "more", "Merge or drop meshes."))
            if element.tag == "include":
                continue
            for key, written in element.attrib.items():
                if not key.startswith("file") or not written:
                    continue
                what = f"{element.tag} file {written!r} of {named_by}"
                file = inside(written, folder / dirs.get(element.tag, ""), roots, f"{element.tag} file", str(named_by))
                data = budget.read(file, what)
                if element.tag == "texture":
                    check_png(data, what)
                digests[written] = hashlib.sha256(data).hexdigest()
    return includes, digests
