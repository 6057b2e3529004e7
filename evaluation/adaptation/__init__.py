"""Adaptation in the loop: (a) the visual marker shifted on the hand (marker_shift.py), (b) gravity jumping to
Jupiter's mid-task (jupiter.py); each with its tables and plots (`*_report.py`)."""

from bodyschema.evaluation.adaptation.jupiter import JupiterConfig, run_jupiter
from bodyschema.evaluation.adaptation.marker_shift import MarkerShiftConfig, run_marker_shift

__all__ = ["JupiterConfig", "MarkerShiftConfig", "run_jupiter", "run_marker_shift"]
