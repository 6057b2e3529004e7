"""Robustness of perception: joint error vs observation noise on one modality, and with each sensor broken.

Both sweeps reuse the levels benchmark (`levels.noise_sweep`, `levels.broken_sweep`) at one level and write a
CSV and a plot each: error vs noise σ (log scale), and a bar per broken modality (precision 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from bodyschema.evaluation.level_report import markdown, plot_sweep, write_csv
from bodyschema.evaluation.levels import DEFAULT_MODELS, LevelsConfig, broken_sweep, noise_sweep, resolve_models


@dataclass(frozen=True)
class RobustnessConfig:
    """Sweep observation noise on one modality and break each modality in turn, at one estimation level."""

    levels: LevelsConfig = field(default_factory=lambda: LevelsConfig(trials=200, runs=1))  # models, trials, seed
    modality: str = "ee_xyz"                        # the modality the noise is added to
    sigmas: tuple[float, ...] = (0.0, 0.001, 0.003, 0.01, 0.03)   # noise std in that modality's unit (m for ee_xyz)
    level: int = 2                                  # strong deviation of all joints: the informative case
    out: Path = Path("results/robustness")


def run_robustness(config: RobustnessConfig, models=None) -> dict[str, Path]:
    models = resolve_models(config.levels.models, DEFAULT_MODELS, config.levels.tracking_uri, models)
    levels = replace(config.levels, out=config.out)
    config.out.mkdir(parents=True, exist_ok=True)
    noise = noise_sweep(levels, config.modality, config.sigmas, level=config.level, models=models)
    broken = broken_sweep(levels, models=models, level=config.level)
    summary = config.out / "summary.md"
    summary.write_text(f"Level {config.level}, observation noise σ on {config.modality} (precisions unchanged):\n\n"
                       f"{markdown(noise, key='sigma')}\nEach modality broken in turn (precision 0):\n\n"
                       f"{markdown(broken, key='broken')}")
    return {"summary_md": summary, "noise_csv": write_csv(noise, config.out / "noise_sweep.csv"),
            "noise_png": plot_sweep(noise, "sigma", config.out / "noise_sweep.png"),
            "broken_csv": write_csv(broken, config.out / "broken_sensor.csv"),
            "broken_png": plot_sweep(broken, "broken", config.out / "broken_sensor.png")}
