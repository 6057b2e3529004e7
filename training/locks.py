"""File locks for training (fcntl.flock): one process per run directory, one writer of the registry at a time.

`flock` locks belong to an open file and vanish when the process dies (even by kill -9), so a lock is never left
behind by a crash and there is nothing to clean up. Two uses:

- `exclusive(path)`: wait for the lock (short critical sections: creating the sqlite tables, registering a
  version and moving the `champion` alias as one compare-and-set);
- `exclusive(path, wait=False)`: refuse at once with `Locked` naming the holder's pid (a run directory: the same
  `bodyschema train` started twice must not attach to the first one's run and checkpoint).

POSIX only (Linux, macOS); flock on NFS is not reliable, so keep run directories and the sqlite file local.
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bodyschema.errors import must_be


class Locked(BlockingIOError):
    """The lock is held by another live process (an OSError: the resource is busy, not a bad value)."""


@contextmanager
def exclusive(path: str | Path, *, wait: bool = True, what: str | None = None, hint: str = "") -> Iterator[None]:
    """Hold an exclusive flock on `path` (created if missing; it holds the holder's pid) for the `with` body.

    wait=False raises `Locked` ("<what> must be free. Got locked by pid N ...") instead of waiting.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            raise Locked(must_be(what or str(path), "free (one process at a time)", f"locked by pid {holder}",
                                 hint)) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)          # closing the file releases the lock


def pid_alive(pid: int, start_ticks: str | None = None) -> bool:
    """Is process `pid` alive (and, when `start_ticks` is given, still the same process, not a reused pid)?"""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass                  # alive, owned by another user
    return start_ticks is None or process_start(pid) in (None, start_ticks)


def process_start(pid: int | None = None) -> str | None:
    """Start time of a process in clock ticks since boot (Linux /proc), to tell a reused pid apart; else None."""
    try:
        stat = Path(f"/proc/{pid or os.getpid()}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]    # field 22 (starttime); fields 1-2 may hold spaces
