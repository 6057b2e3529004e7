"""Processes by pid and start time (Linux /proc): is a recorded process still the same one, and what did it start.

A pid is reused once its process is gone; its start time (clock ticks since boot) tells the two apart. Used by
training's run directories (is the run that wrote this still alive?) and the local Ray's reaper (base/ray_session.py).
"""

from __future__ import annotations

import os

WATCH_S = 0.5  # s between checks of a watched pid: a watcher acts at most this long after its process is gone


def stat_field(pid: int, index: int) -> int | None:
    """Field `index` (0-based, as in proc(5) minus one) of /proc/<pid>/stat; None when the process is gone."""
    try:
        text = open(f"/proc/{pid}/stat").read()
    except OSError:
        return None
    fields = text.rpartition(")")[2].split()                # after the command name, which may hold spaces
    try:
        return int(fields[index - 2])
    except (IndexError, ValueError):
        return None


def start_time(pid: int) -> int | None:
    """The start time of process `pid` (clock ticks since boot); None: no such process (or no /proc)."""
    return stat_field(pid, 21)


def process_start(pid: int | None = None) -> str | None:
    """`start_time` of `pid` (default: this process) as text, as run directories record it; None without /proc."""
    started = start_time(pid or os.getpid())
    return None if started is None else str(started)


def pid_alive(pid: int, start_ticks: str | None = None) -> bool:
    """Is process `pid` alive (and, when `start_ticks` is given, still the same process, not a reused pid)?"""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass                  # alive, owned by another user
    return start_ticks is None or process_start(pid) in (None, start_ticks)
