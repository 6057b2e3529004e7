"""Robot model file formats, one row each: a file suffix → the reader turning such a file into a MuJoCo spec.

A reader is `read(path, text, record, budget) -> (spec, meshes, replaced)`: the `mujoco.MjSpec` of the file's
`text` read from `path`, {mesh path as written: sha256} of the files it read, and {link: meshes drawn as primitives}
(URDF's `visual = "primitives"`, else {}). It reads every file it needs through `budget` (model_files.Budget: the
file policy of README "Your own robot"). A shipped reader is named "module:function" and imported on first use, so
that checking a record's `model` suffix imports no MuJoCo; `register` adds a row at run time (a callable is fine).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from bodyschema.errors import must_be


@dataclass(frozen=True)
class Format:
    name: str                      # as users know it: "MJCF", "URDF"
    suffix: str                    # lower case, with the dot
    reader: str | Callable         # "module:function", or the function itself

    def read(self, *args):
        reader = self.reader
        if isinstance(reader, str):
            module, _, function = reader.partition(":")
            reader = getattr(importlib.import_module(module), function)
        return reader(*args)


FORMATS: dict[str, Format] = {f.suffix: f for f in (
    Format("MJCF", ".xml", "bodyschema.datagen.body.mjcf:read_mjcf"),
    Format("URDF", ".urdf", "bodyschema.datagen.body.urdf:read_urdf"),
)}


def register(row: Format) -> Format:
    """Add a format (a plugin's, a test's); its suffix must be new."""
    if not (row.suffix.startswith(".") and row.suffix == row.suffix.lower()) or row.suffix in FORMATS:
        raise ValueError(must_be("a new format's suffix", f"a new lower-case suffix with its dot, not one of "
                                 f"{sorted(FORMATS)}", row.suffix))
    FORMATS[row.suffix] = row
    return row


def unregister(suffix: str) -> None:
    FORMATS.pop(suffix, None)


def suffixes() -> tuple[str, ...]:
    return tuple(FORMATS)


def described() -> str:
    """"MJCF (.xml) or URDF (.urdf)": the formats in words, for messages."""
    names = [f"{f.name} ({f.suffix})" for f in FORMATS.values()]
    return " or ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)


def of(path: Path) -> Format:
    """The format of a model file, by its suffix; the house error for another suffix."""
    row = FORMATS.get(Path(path).suffix.lower())
    if row is None:
        raise ValueError(must_be("a robot model file", f"an {described()} file", str(path),
                                 "Other formats: convert them to one of these first."))
    return row
