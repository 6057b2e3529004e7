"""Motor babbling datasets: generate (`DatagenConfig`, `generate`), check (`validate_store`), look
(`summarize_store`, `show_store`, `write_contact_sheet`) and export (`export_dataset`: HDF5, LeRobot).

Names are imported on first use: `generate` pulls in MuJoCo, which reading a store never needs.
"""

from __future__ import annotations

from bodyschema.lazy import lazy_exports

_EXPORTS = {"DatagenConfig": "config", "generate": "generate", "validate_store": "validate",
            "summarize_store": "validate", "show_store": "show", "write_contact_sheet": "contact_sheet",
            "export_dataset": "export", "open_store": "store"}

__all__, __getattr__, __dir__ = lazy_exports(
    "bodyschema.datagen", globals(),
    {name: (f"bodyschema.datagen.{module}", name) for name, module in _EXPORTS.items()})
