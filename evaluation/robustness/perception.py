"""Robustness of perception: joint error vs observation noise on one modality, and with each sensor broken.

Both sweeps reuse the levels benchmark (`levels.benchmark.noise_sweep`, `broken_sweep`) at one level and write a
CSV and a plot each: error vs noise σ (log scale), and a bar per broken modality (precision 0).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from bodyschema.errors import must_be
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.specs import resolve_models
from bodyschema.evaluation.core.tables import write_csv
from bodyschema.evaluation.levels.benchmark import DEFAULT_MODELS, PerceptionRunConfig, broken_sweep, noise_sweep
from bodyschema.evaluation.levels.report import markdown, plot_sweep
from bodyschema.evaluation.robustness.units import noise_label


@dataclass(frozen=True)
class RobustnessConfig(PerceptionRunConfig):
    """Sweep observation noise on one modality and break each modality in turn, at one estimation level."""

    out: Path = Path("results/robustness")           # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-robustness"        # the MLflow experiment
    trials: int = 200                               # per run and case
    runs: int = 1                                   # runs with different target seeds
    modality: str = "ee_xyz"                        # the modality the noise is added to
    sigmas: tuple[float, ...] = (0.0, 0.001, 0.003, 0.01, 0.03)   # noise std in that modality's unit (m for ee_xyz)
    level: int = 2                                  # strong deviation of all joints: the informative case

    def __post_init__(self):
        super().__post_init__()
        if self.level not in (1, 2, 3):     # checked now, not after the models are loaded, and under its own name
            raise ValueError(must_be("level", "1, 2 or 3 (an estimation level)", self.level))


def run_robustness(config: RobustnessConfig = RobustnessConfig(), models=None) -> dict[str, Path]:
    """Both sweeps; tables and plots in a new run folder under config.out, one MLflow run."""
    models = resolve_models(config.models, DEFAULT_MODELS, config.tracking_uri, models)
    noise = noise_sweep(config, config.modality, config.sigmas, level=config.level, models=models)
    broken = broken_sweep(config, models=models, level=config.level)
    out = new_run(config)
    summary = out / "summary.md"
    summary.write_text(f"Level {config.level}, observation noise σ on {config.modality} (precisions unchanged):\n\n"
                       f"{markdown(noise, key='sigma')}\nEach modality broken in turn (precision 0):\n\n"
                       f"{markdown(broken, key='broken')}")
    paths = {"summary_md": summary, "noise_csv": write_csv(noise, out / "noise_sweep.csv"),
             "broken_csv": write_csv(broken, out / "broken_sensor.csv")}
    if config.plots:
        error = "joint error after perception (deg, mean over joints and trials)"   # joint_err_deg
        paths.update(noise_png=plot_sweep(noise, "sigma", out / "noise_sweep.png", xlabel=noise_label(config.modality),
                                          ylabel=error),
                     broken_png=plot_sweep(broken, "broken", out / "broken_sensor.png", xlabel="broken sensor",
                                           ylabel=error))
    metrics = {**table_metrics(noise, lambda r: f"sigma {r['sigma']:g}"), **table_metrics(broken, "broken")}
    publish(config, out, "robustness", metrics, paths, models)
    return paths
