"""Axis labels with units for the robustness plots: observation noise σ is added in the modality's own unit
(evaluation/core/sensing.py: joint angles in rad, positions in m, pixels in px, image intensity in [0, 1])."""

from __future__ import annotations

from bodyschema.base import modalities


def noise_label(modality: str) -> str:
    """'observation noise σ on ee_xyz (m)'; a modality without a known unit is named without one."""
    unit = modalities.unit(modality)
    return f"observation noise σ on {modality}" + (f" ({unit})" if unit else "")
