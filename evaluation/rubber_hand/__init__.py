"""The rubber-hand illusion: the benchmark (benchmark.py), the resting arm and the seen hand (scene.py), stroking and
the belief that the seen hand is mine (stroking.py), tables and plots (report.py)."""

from bodyschema.evaluation.rubber_hand.benchmark import RubberHandConfig, run_rubber_hand

__all__ = ["RubberHandConfig", "run_rubber_hand"]
