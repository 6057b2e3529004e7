"""The remedies a `validate_store` line ends with: what the user does about a problem of a generated store.

An importer strips them from the lines it shows (writer.py): for an imported store, the recording is at fault.
"""

RESUME_HINT = "Rerun the same `bodyschema datagen` command to resume it."
REPAIR_HINT = "Rerun the same `bodyschema datagen` command: it rewrites the damaged shards."
REGENERATE_HINT = "The generator wrote impossible values; regenerate with --overwrite and report it."
EDITED_HINT = "The store's attrs were edited or come from another robot; regenerate it with `bodyschema datagen`."
