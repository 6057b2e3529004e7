"""Motor babbling datasets: generate (`DatagenConfig`, `generate`), check (`validate_store`), look
(`summarize_store`, `show_store`, `write_contact_sheet`) and export (`export_dataset`: HDF5, LeRobot).

Names are imported on first use: `generate` pulls in MuJoCo, which reading a store never needs.
"""

from __future__ import annotations

from bodyschema.lazy import lazy_exports

_EXPORTS = {"DatagenConfig": "config", "generate": "generate", "validate_store": "store.validate",
            "summarize_store": "store.validate", "show_store": "store.show",
            "write_contact_sheet": "store.contact_sheet", "export_dataset": "exchange.export",
            "open_store": "store.schema"}

__all__, __getattr__, __dir__ = lazy_exports(
    "bodyschema.datagen", globals(),
    {name: (f"bodyschema.datagen.{module}", name) for name, module in _EXPORTS.items()})
