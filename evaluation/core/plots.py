"""The plotting helper of every benchmark: matplotlib on the file-only Agg backend and one way to save a figure.

Benchmarks import plotting from here only. The project keeps a single `save_figure` (training/plots.py, which
also sets the Agg backend before pyplot loads); this module is evaluation's one door to it, so a change of
backend, dpi or layout policy for benchmark plots is made here."""

from __future__ import annotations

from bodyschema.training.plots import plt, save_figure

__all__ = ["plt", "save_figure"]
