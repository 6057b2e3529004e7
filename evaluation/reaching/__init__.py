"""Closed-loop reaching: the benchmark (benchmark.py, on the control layer's loop and policies, `bodyschema.control`),
metrics, tables and plots (report.py), and its AIF controller as a policy on a `ReachEnv` (env_policy.py, loaded
on first use: it needs gymnasium's envs)."""

from bodyschema.evaluation.reaching.benchmark import ReachingConfig, ReachingRunConfig, run_reaching

__all__ = ["AIFPolicy", "ReachingConfig", "ReachingRunConfig", "run_reaching"]


def __getattr__(name: str):
    if name == "AIFPolicy":
        from bodyschema.evaluation.reaching.env_policy import AIFPolicy
        return AIFPolicy
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
