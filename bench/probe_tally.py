"""What the three probe scripts (bench/probe.py, probe_library.py, probe_races.py) print alike: a process's last
line of stderr, and one tally line per kind of case."""

from __future__ import annotations

from collections import Counter


def last_line(stderr: str, width: int = 200) -> str:
    """The last line a process wrote (its error, where it failed), cut to `width` characters."""
    return (stderr.strip().splitlines() or [""])[-1][:width]


def print_tally(label: str, tally: Counter, outcomes: tuple[str, ...], odd: list[str]) -> None:
    """`<label> <total>: outcome n / …`, then the cases that did not end as the first outcome."""
    print(f"{label} {sum(tally.values())}: " + " / ".join(f"{name} {tally[name]}" for name in outcomes))
    print("\n".join(odd))
