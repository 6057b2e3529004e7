"""Robustness to noise and broken sensors: of perception at one estimation level (perception.py) and of the closed
reaching loop (loop.py)."""

from bodyschema.evaluation.robustness.loop import LoopRobustnessConfig, run_loop_robustness
from bodyschema.evaluation.robustness.perception import RobustnessConfig, run_robustness

__all__ = ["LoopRobustnessConfig", "RobustnessConfig", "run_loop_robustness", "run_robustness"]
