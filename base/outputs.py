"""Where an export writes OUT: beside it first, then renamed into place; only a previous output of its kind is replaced.

    write_atomically(out, write, overwrite, kind=..., inputs=..., need_bytes=..., source=...)

- OUT must not exist, or (with overwrite) be a previous output of the same kind: recognised by the marker JSON
  written beside it (`.<name>.bodyschema-output.json`: the kind, the source, and a fingerprint of OUT: a file's
  sha256, a directory's file list with sizes), so a foreign file or folder later put in its place is not taken
  for it. Beside, not inside: a file inside a Zarr store makes zarr warn on every read. The export's inputs, a
  folder holding them and a folder inside them are never replaced, marker or not.
- Before writing: partials of the same OUT left by a killed export (a pid no longer alive) are removed, and the
  free space beside OUT is checked against the caller's estimate.
- One writer per OUT: the whole write holds OUT's lock (`locks.store_lock`, the one datagen holds), and OUT is
  checked again under it; a second writer is refused naming the holder's pid, or finds OUT written.
- `write(tmp)` builds the output at `.<name>.partial-<pid>`; any failure (Ctrl-C included) removes it, and a full
  disk is named as such. A new OUT is moved in with a rename that fails when OUT appeared meanwhile (renameat2
  RENAME_NOREPLACE; a hard link for a file where that is missing), so nothing is silently replaced; --overwrite
  moves a file in with one `os.replace`, a directory by renaming the old one aside, the new one in, then deleting
  the old one. Folders made for OUT are removed again when nothing is written.
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import json
import os
import re
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from bodyschema.base.locks import store_lock
from bodyschema.errors import must_be

MARKER = "bodyschema-output.json"
ANY_OUTPUT = "bodyschema-output"        # the kind of a caller that names none (the importer's stores)
FULL_DISK = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)
# h5py and pyarrow put the OS error in their message text rather than in `errno`
FULL_DISK_TEXT = re.compile(r"errno = (28|27|122)\b|No space left|File too large|quota exceeded", re.I)
MARGIN_BYTES = 2 ** 20                  # metadata beside the data (headers, indexes, the marker)


def write_atomically(out: str | Path, write: Callable[[Path], None], overwrite: bool, *, kind: str = ANY_OUTPUT,
                     inputs: Iterable[str | Path] = (), need_bytes: int = 0, source: Any = None) -> Path:
    """Run `write(tmp)` on a temporary sibling of `out`, then move it to `out`; returns `out` as given."""
    given, out = Path(out), Path(out).resolve()
    check_out(out, kind, overwrite, inputs)
    made = [p for p in reversed(out.parents) if not p.exists()]
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with store_lock(out, f"OUT {out}", LOCKED_HINT):
            check_out(out, kind, overwrite, inputs)     # again: another writer may have finished meanwhile
            replace_atomically(out, lambda tmp: _write_with_marker(tmp, write, kind, source), need_bytes,
                               replace=out.exists() or out.is_symlink())
    except BaseException:
        for folder in reversed(made):                   # the folders made for OUT, when they stayed empty
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    return given


LOCKED_HINT = ("Another bodyschema command (import, export or datagen) is writing it; wait for it to finish and "
               "choose another path (or pass --overwrite), or stop that process. Nothing was written.")


def check_out(out: str | Path, kind: str, overwrite: bool, inputs: Iterable[str | Path] = ()) -> None:
    """Refuse an OUT that is or holds an input, or exists and is not (or not asked to be replaced as) our output."""
    out = Path(out).resolve()
    for source in map(lambda p: Path(p).resolve(), inputs):
        if out == source or out in source.parents or source in out.parents:
            raise FileExistsError(must_be("OUT", "a path outside the input", str(out),
                                          f"It is, holds or lies inside {source}; choose another path. "
                                          "Nothing was deleted."))
    if not out.exists():
        return
    if not overwrite:
        raise FileExistsError(must_be("OUT", "a path that does not exist yet", str(out),
                                      "Pass --overwrite to replace it, or choose another path."))
    found = marker_of(out)
    if found.get("format") != kind:
        what = f"a {found['format']} output" if found.get("format") else "not written by this command"
        raise FileExistsError(must_be("OUT", f"a previous {kind} output to be replaced by --overwrite",
                                      f"{out} ({what})", "Only an output carrying this command's marker is "
                                      "replaced; choose another path or remove it yourself. Nothing was deleted."))


def marker_of(out: Path) -> dict[str, Any]:
    """The marker of an existing output, {} when it has none or it describes another file or folder."""
    try:
        found = json.loads(marker_path(out).read_text())
        return found if isinstance(found, dict) and found.get("fingerprint") == fingerprint(out) else {}
    except (OSError, ValueError):       # no marker, not JSON, or OUT unreadable (a dangling link inside)
        return {}


def marker_path(out: Path) -> Path:
    return out.with_name(f".{out.name}.{MARKER}")


def fingerprint(path: Path) -> str:
    """sha256 of a file's bytes, or of a directory's file list (relative paths and sizes)."""
    h = hashlib.sha256()
    if path.is_dir():
        for p in sorted(path.rglob("*")):
            h.update(f"{p.relative_to(path).as_posix()}\0{p.stat().st_size if p.is_file() else -1}\n".encode())
        return "files:" + h.hexdigest()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(2 ** 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()


def _write_with_marker(tmp: Path, write: Callable[[Path], None], kind: str, source: Any) -> None:
    """`write(tmp)`, then its marker at `<tmp>.json` (`replace_atomically` moves both; the fingerprint of a
    directory is relative to it, so it holds after the rename)."""
    write(tmp)
    marker = {"format": kind, "source": source, "fingerprint": fingerprint(tmp)}
    Path(f"{tmp}.json").write_text(json.dumps(marker, indent=2, default=str))


def replace_atomically(out: Path, write: Callable[[Path], None], need_bytes: int = 0, replace: bool = True) -> None:
    """`write(tmp)` at `.<name>.partial-<pid>`, then moved to `out` (and `<tmp>.json`, if written, to the marker's).
    First the partials of `out` left by killed processes go, and the free space is checked against `need_bytes`.
    replace=False: `out` must still not exist when the output is moved in (else FileExistsError, nothing moved)."""
    remove_stale_partials(out)
    check_free_space(out.parent, need_bytes)
    tmp = partial_path(out, os.getpid())
    aside, marker_tmp = Path(f"{tmp}.old"), Path(f"{tmp}.json")
    try:
        write(tmp)
        if not replace:
            rename_new(tmp, out)
        else:
            if tmp.is_dir() and out.is_dir():
                os.rename(out, aside)
            os.replace(tmp, out)
        if marker_tmp.exists():
            os.replace(marker_tmp, marker_path(out))
    except BaseException as error:      # Ctrl-C included: nothing half-written stays
        for path in (tmp, marker_tmp):
            _remove(path)
        if aside.exists() and not out.exists():
            os.rename(aside, out)       # the old output back where it was
        if isinstance(error, Exception) and is_disk_full(error):
            raise OSError(must_be("the disk holding OUT", "one with room for the export",
                                  f"disk full: {_first_line(error)}", f"Free space or choose another path for "
                                  f"{out}; the partial output was removed, nothing was written.")) from error
        raise
    _remove(aside)


RENAME_NOREPLACE, AT_FDCWD = 1, -100      # linux/fs.h, fcntl.h


def rename_new(tmp: Path, out: Path) -> None:
    """Move `tmp` to `out`, which must not exist: a FileExistsError (the house message) when it appeared meanwhile,
    and `tmp` stays where it was. renameat2(RENAME_NOREPLACE) where the kernel and file system have it; else a hard
    link for a file (fails on an existing name) and, for a directory, a check just before the rename."""
    try:
        if _renameat2_noreplace(tmp, out):
            return
        if not tmp.is_dir():
            os.link(tmp, out)
            os.unlink(tmp)
            return
        if out.exists() or out.is_symlink():
            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(out))
        os.rename(tmp, out)
    except FileExistsError:
        raise FileExistsError(must_be("OUT", "a path that does not exist yet", f"{out} (it appeared while this "
                                      "command was writing)", "Another process wrote it meanwhile and it was kept; "
                                      "choose another path, or pass --overwrite to replace it.")) from None


def _renameat2_noreplace(tmp: Path, out: Path) -> bool:
    """True when renameat2 moved `tmp` to `out`; False where it is unavailable (an older libc, a file system
    without RENAME_NOREPLACE); FileExistsError when `out` exists."""
    renameat2 = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if renameat2 is None:
        return False
    if renameat2(AT_FDCWD, os.fsencode(tmp), AT_FDCWD, os.fsencode(out), RENAME_NOREPLACE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    if code == errno.EEXIST:
        raise FileExistsError(code, os.strerror(code), str(out))
    raise OSError(code, os.strerror(code), str(out))


def partial_path(out: Path, pid: int) -> Path:
    return out.with_name(f".{out.name}.partial-{pid}")


def remove_stale_partials(out: Path) -> None:
    """Remove the partials of `out` left by killed exports: their pid is gone (or they predate pids)."""
    pattern = re.compile(rf"\.{re.escape(out.name)}\.partial(?:-(\d+))?(?:\.old|\.json)?")
    for path in out.parent.iterdir():
        match = pattern.fullmatch(path.name)
        if match and not (match.group(1) and _writing(int(match.group(1)))):
            _remove(path)


def _writing(pid: int) -> bool:
    """Whether process `pid` may still be writing its partial: alive, and not this process (which is about to)."""
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:             # someone else's process: alive
        return True
    return True


def check_free_space(folder: Path, need_bytes: int) -> None:
    """Refuse before writing when the free space at `folder` is below the estimate (plus a margin)."""
    need, free = need_bytes + MARGIN_BYTES, shutil.disk_usage(folder).free
    if free < need:
        raise OSError(must_be("the free space beside OUT", f">= {need / 1e6:.1f} MB (the export's estimated size)",
                              f"{free / 1e6:.1f} MB free at {folder}",
                              "Free space or choose another path; nothing was written."))


def is_disk_full(error: BaseException) -> bool:
    """True for a write refused for lack of space (ENOSPC, a file-size limit, a quota), wherever it is said."""
    chain = [error, error.__cause__, error.__context__]
    return any(isinstance(e, OSError) and e.errno in FULL_DISK for e in chain) or any(
        e is not None and FULL_DISK_TEXT.search(str(e)) for e in chain)


def _first_line(error: BaseException) -> str:
    return next((line.strip() for line in str(error).splitlines() if line.strip()), type(error).__name__)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()
