"""The base layer every stage may import: atomic outputs, locks, the Ray session, the modality table."""
