"""`bodyschema reproduce`: the README's measured tables regenerated from its own commands (run.py)."""
