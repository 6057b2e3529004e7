"""Which files the report may read: a run's own files, judged on their real path (symlinks and `..` resolved), so a
link in a summary.md, or a symlink in a run folder, cannot make the report read and embed a file from elsewhere."""

from __future__ import annotations

from pathlib import Path


def resolved(path: Path) -> Path | None:
    """The real path of `path` (it need not exist); None when it has none (a NUL byte, a symlink loop)."""
    try:
        return Path(path).resolve()
    except (OSError, RuntimeError, ValueError):
        return None


def is_inside(path: Path, folder: Path) -> bool:
    """`path` is `folder` or below it once both are resolved."""
    real, root = resolved(path), resolved(folder)
    return real is not None and root is not None and real.is_relative_to(root)
