"""A store read in row blocks: what every exporter reads at a time (export.py checks the store, export_hdf5.py and
export_lerobot.py write it; both import this, not export.py, which picks between them)."""

from __future__ import annotations

ROWS_PER_READ = 4096          # rows read from the store at a time: images of 4096 × 56 × 80 are 18 MB


def row_blocks(n: int, step: int | None = None):
    """(start, stop) ranges covering [0, n) in steps of `step` rows (default ROWS_PER_READ)."""
    step = step or ROWS_PER_READ
    return ((start, min(n, start + step)) for start in range(0, n, step))
