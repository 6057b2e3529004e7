"""Files written whole or not at all: a saved model and a training checkpoint never end half-written.

Every file goes to a `<name>.tmp` sibling first and is renamed into place only once all of them are written, so a
full disk, a file-size limit or Ctrl-C in the middle leaves the previous files as they were and no temporary
behind. A failed write is raised as an OSError naming the file (Python's own names none), which the CLI reports
as a full disk rather than as a damaged input.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import torch


def torch_bytes(obj) -> bytes:
    """What `torch.save(obj, file)` would write, in memory: the disk is touched by `write_atomically` only."""
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def write_atomically(files: dict[Path, bytes]) -> None:
    """Write every `path: data`; on any failure none of the paths has changed and the temporaries are gone."""
    temporaries = {Path(path): Path(path).with_name(Path(path).name + ".tmp") for path in files}
    try:
        for path, tmp in temporaries.items():
            _write(tmp, files[path], path)
        for path, tmp in temporaries.items():
            os.replace(tmp, path)
    finally:
        for tmp in temporaries.values():
            tmp.unlink(missing_ok=True)            # already renamed on success


def _write(tmp: Path, data: bytes, target: Path) -> None:
    try:
        with open(tmp, "wb") as file:
            file.write(data)
    except OSError as error:
        raise OSError(error.errno, error.strerror, str(target)) from error
