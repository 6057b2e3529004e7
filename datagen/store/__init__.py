"""The dataset store (Zarr v3): schema, writes, reads, integrity, validation and a look at it."""
