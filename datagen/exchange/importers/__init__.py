"""`bodyschema import`: recordings of a real (or simulated) arm into a dataset store of the Zarr v3 schema.

One module per source format, each returning a `Recording` (recording.py): a folder of images plus a CSV of joint
angles (folder_csv.py), HDF5 in this project's export layout or a robot-learning demo layout (hdf5.py), a LeRobot
v3.0 dataset (lerobot.py). The body (body.py) comes from a shipped robot or from `--joints` with `--ranges`; images
are cropped, resized and converted (images.py); the shared writer (writer.py) checks everything, writes the store
beside its final path, validates it and renames it into place.
"""

from __future__ import annotations

from bodyschema.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    "bodyschema.datagen.exchange.importers", globals(),
    {"import_recording": ("bodyschema.datagen.exchange.importers.run", "import_recording"),
     "ImportConfig": ("bodyschema.datagen.exchange.importers.config", "ImportConfig")})
