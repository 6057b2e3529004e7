"""One writer per store: an exclusive flock on `<store>.lock` beside it, held for the whole run — by datagen, and
by every command that renames an output into place (import, export: datagen/outputs.py), so two of them writing one
path never both succeed.

The mechanism of `training/locks.py` (fcntl.flock, the holder's pid written in the file): the kernel drops the lock
when its process dies, even by kill -9, so a dead run's lock is simply taken over. The file lives beside the store,
not inside it: `--overwrite` deletes the store, and a lock file deleted while held would let a second run lock a
new file of the same name. The holder removes it on exit; a run that opened the old file meanwhile sees that the
path no longer names the file it locked and tries again. (datagen cannot import training: no back edge.)
POSIX only; flock on NFS is not reliable.
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bodyschema.errors import must_be


class StoreLocked(BlockingIOError):
    """Another live process is writing the store (an OSError: the resource is busy, not a bad value)."""


def lock_path(store: Path) -> Path:
    """The lock file of a store: `<name>.lock` beside it."""
    return store.with_name(store.name + ".lock")


DATAGEN_HINT = ("Another bodyschema run (datagen, import or export) is writing it; wait for it to finish (the same "
                "command then finds the store complete) or stop that process.")


@contextmanager
def store_lock(store: Path, what: str | None = None, hint: str = DATAGEN_HINT) -> Iterator[None]:
    """Hold the store's lock for the `with` body; raise `StoreLocked` naming the holder's pid if it is taken.
    `what` names the output in that error (default "the store <path>")."""
    path = lock_path(store)
    fd = _lock_current_file(path, what or f"the store {store}", hint)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        path.unlink(missing_ok=True)  # still locked here: a run that opened this file retries on the new one
        os.close(fd)  # closing the file releases the lock


def _lock_current_file(path: Path, what: str, hint: str) -> int:
    """An fd holding the flock of the file `path` names now (not one its holder has just removed)."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise StoreLocked(must_be(what, "free (one bodyschema writer at a time: datagen, import or export)",
                                      f"locked by pid {holder}", hint)) from None
        if _same_file(fd, path):
            return fd
        os.close(fd)


def _same_file(fd: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path))
    except FileNotFoundError:
        return False
