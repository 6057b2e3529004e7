"""Test helpers over Linux /proc: a process's descendants, whether a pid still runs, and listening sockets."""

from __future__ import annotations

import ipaddress
import os
from pathlib import Path

PROC = Path("/proc")
TCP_LISTEN, UDP_UNCONNECTED = "0A", "07"


def _stat(pid: int) -> list[str] | None:
    try:
        return (PROC / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()  # [state, ppid, ...]
    except (OSError, IndexError):
        return None


def running(pid: int) -> bool:
    """True while `pid` exists and is not a zombie (a zombie has exited; only its parent has not reaped it)."""
    stat = _stat(pid)
    return stat is not None and stat[0] not in ("Z", "X")


def descendants(root: int) -> set[int]:
    """Every live process below `root` (children, their children, ...)."""
    children: dict[int, list[int]] = {}
    for entry in PROC.iterdir():
        if entry.name.isdigit() and (stat := _stat(int(entry.name))) is not None:
            children.setdefault(int(stat[1]), []).append(int(entry.name))
    out, todo = set(), [root]
    while todo:
        for kid in children.get(todo.pop(), []):
            if kid not in out:
                out.add(kid)
                todo.append(kid)
    return {pid for pid in out if running(pid)}


def _address(hex_addr: str) -> str:
    host, port = hex_addr.split(":")
    raw = bytes.fromhex(host)
    # /proc prints each 32-bit word in host (little-endian) order
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    return f"{ipaddress.ip_address(words)}:{int(port, 16)}"


def _socket_inodes(pid: int) -> set[str]:
    inodes = set()
    try:
        for fd in (PROC / str(pid) / "fd").iterdir():
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    except OSError:
        pass
    return inodes


def listening(pids: set[int]) -> list[tuple[int, str, str]]:
    """(pid, proto, "ip:port") of every TCP listening or unconnected UDP socket the processes `pids` hold."""
    owner = {inode: pid for pid in pids for inode in _socket_inodes(pid)}
    out = []
    for proto in ("tcp", "tcp6", "udp", "udp6"):
        try:
            lines = (PROC / "net" / proto).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            local, state, inode = fields[1], fields[3], fields[9]
            if inode in owner and state == (TCP_LISTEN if proto.startswith("tcp") else UDP_UNCONNECTED):
                out.append((owner[inode], proto, _address(local)))
    return out


def is_loopback(address: str) -> bool:
    """True for 127.0.0.0/8, ::1 and IPv4-mapped loopback (::ffff:127.x); wildcards (0.0.0.0, ::) are not."""
    ip = ipaddress.ip_address(address.rsplit(":", 1)[0])
    mapped = getattr(ip, "ipv4_mapped", None)
    return (mapped or ip).is_loopback
