"""Motor babbling datasets: generate (`DatagenConfig`, `generate`), check (`validate_store`), look
(`summarize_store`, `show_store`, `write_contact_sheet`) and export (`export_dataset`: HDF5, LeRobot).

Names are imported on first use: `generate` pulls in MuJoCo, which reading a store never needs.
"""

from __future__ import annotations

import importlib

_EXPORTS = {"DatagenConfig": "config", "generate": "generate", "validate_store": "validate",
            "summarize_store": "validate", "show_store": "show", "write_contact_sheet": "contact_sheet",
            "export_dataset": "export", "open_store": "store"}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'bodyschema.datagen' has no attribute {name!r}")
    return getattr(importlib.import_module(f"bodyschema.datagen.{_EXPORTS[name]}"), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
