"""`BenchmarkConfig`: the fields every benchmark shares, declared once; a benchmark's config derives from it and
sets its own `out` and `experiment` defaults."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from bodyschema.errors import must_be


@dataclass(frozen=True)
class BenchmarkConfig:
    """Shared by every benchmark: seeding, where runs go, MLflow, progress bars."""

    seed: int = 0                      # seeds every random draw of the run (targets, starts, noise)
    out: Path = Path("results")        # the benchmark's folder: a run writes <out>/<run-id>/ and links <out>/latest
    mlflow: bool = True                # log the run (config, metrics, files, the models it used) to MLflow
    tracking_uri: str | None = None    # None: $MLFLOW_TRACKING_URI, else sqlite:///mlflow.db
    experiment: str = "bodyschema"     # the MLflow experiment of the run
    progress: bool = True              # show progress bars

    def __post_init__(self):
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(must_be("seed", "an integer ≥ 0", self.seed))


@dataclass(frozen=True)
class TrialsConfig(BenchmarkConfig):
    """A benchmark of independent trials: `--trials` counts them (targets, episodes, goal poses alike)."""

    trials: int = 100                  # independent trials (episodes) of the run

    def __post_init__(self):
        super().__post_init__()
        if not isinstance(self.trials, int) or self.trials < 1:
            raise ValueError(must_be("trials", "at least 1", self.trials))


def check_names(name: str, values: tuple[str, ...], allowed: tuple[str, ...]) -> None:
    """The house error unless `values` is a non-empty tuple of distinct names among `allowed`."""
    if not values or len(set(values)) != len(values) or set(values) - set(allowed):
        raise ValueError(must_be(name, f"distinct names among {allowed}", values))
