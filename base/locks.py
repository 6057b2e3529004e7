"""File locks (fcntl.flock): one writer per store, one process per run directory, one registry writer at a time.

`flock` locks belong to an open file and vanish when the process dies (even by kill -9): a dead holder's lock is
simply taken over, nothing is left to clean up. The holder's pid is written in the file, for the error message.
- `exclusive(path)`: wait for the lock (short critical sections: creating the sqlite tables, registering a version
  and moving the `champion` alias as one compare-and-set); `wait=False` refuses at once with `Locked` naming the
  holder (a run directory: the same `bodyschema train` started twice must not attach to the first one's run).
- `store_lock(store)`: `<store>.lock` beside a dataset store or any output renamed into place (datagen, import,
  export, ONNX: base/outputs.py), held for the whole run, refused at once when taken. The file lives beside the
  store, not inside it: `--overwrite` deletes the store, and a lock file deleted while held would let a second run
  lock a new file of the same name. The holder removes it on exit; a run that opened the old file meanwhile sees
  that the path no longer names the file it locked and tries again.
POSIX only (Linux, macOS); flock on NFS is not reliable, so keep stores, run directories and the sqlite file local.
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bodyschema.errors import must_be

STORE_HINT = ("Another bodyschema run (datagen, import or export) is writing it; wait for it to finish (the same "
              "command then finds the store complete) or stop that process.")
ONE_WRITER = "free (one bodyschema writer at a time: datagen, import or export)"


class Locked(BlockingIOError):
    """The lock is held by another live process (an OSError: the resource is busy, not a bad value)."""


def lock_path(store: Path) -> Path:
    """The lock file of a store: `<name>.lock` beside it."""
    return store.with_name(store.name + ".lock")


def store_lock(store: Path, what: str | None = None, hint: str = STORE_HINT):
    """Hold the store's lock for the `with` body; raise `Locked` naming the holder's pid if it is taken.
    `what` names the output in that error (default "the store <path>")."""
    return exclusive(lock_path(store), wait=False, what=what or f"the store {store}", hint=hint,
                     expected=ONE_WRITER, remove=True, make_parent=False)


@contextmanager
def exclusive(path: str | Path, *, wait: bool = True, what: str | None = None, hint: str = "",
              expected: str = "free (one process at a time)", remove: bool = False,
              make_parent: bool = True) -> Iterator[None]:
    """Hold an exclusive flock on `path` (created if missing; it holds the holder's pid) for the `with` body.

    wait=False raises `Locked` ("<what> must be <expected>. Got locked by pid N ...") instead of waiting.
    remove=True deletes the file on exit, still locked (a store's lock file: see the module docstring).
    make_parent=False: a missing folder is the caller's error to report (an output's), not one to create.
    """
    path = Path(path)
    if make_parent:
        path.parent.mkdir(parents=True, exist_ok=True)
    fd = _lock_current_file(path, wait, lambda holder: Locked(must_be(what or str(path), expected,
                                                                       f"locked by pid {holder}", hint)))
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        if remove:
            path.unlink(missing_ok=True)  # still locked here: a run that opened this file retries on the new one
        os.close(fd)                      # closing the file releases the lock


def _lock_current_file(path: Path, wait: bool, refusal) -> int:
    """An fd holding the flock of the file `path` names now (not one its holder has just removed)."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise refusal(holder) from None
        if _same_file(fd, path):
            return fd
        os.close(fd)


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path))
    except FileNotFoundError:
        return False
