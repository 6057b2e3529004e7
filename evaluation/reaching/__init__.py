"""Closed-loop reaching: the benchmark (benchmark.py), its control loop and policies (loop.py), metrics, tables and
plots (report.py)."""

from bodyschema.evaluation.reaching.benchmark import ReachingConfig, ReachingRunConfig, run_reaching

__all__ = ["ReachingConfig", "ReachingRunConfig", "run_reaching"]
