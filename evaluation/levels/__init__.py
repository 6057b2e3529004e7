"""Estimation levels 1–3, "where is my body?" (benchmark.py), its targets and beliefs (targets.py), tables and plots
(report.py)."""

from bodyschema.evaluation.levels.benchmark import LevelsConfig, LevelsSummary, PerceptionRunConfig, run_levels

__all__ = ["LevelsConfig", "LevelsSummary", "PerceptionRunConfig", "run_levels"]
