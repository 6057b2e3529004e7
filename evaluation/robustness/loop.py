"""Robustness of closed-loop reaching: AIF success rate vs observation noise on one modality, and with each sensor
broken — its precision set to 0 (the controller knows) or its stream frozen at its first reading (it does not).

Every case reruns the reaching benchmark (reaching/benchmark.py) on the same targets and start poses, AIF only,
and keeps its summary row. Writes `noise_sweep.csv/png`, `broken_sensor.csv/png`, `summary.md`, `summary.csv`
into a new run folder and, when `mlflow` is on, one MLflow run with them as artifacts.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from bodyschema.base import modalities
from bodyschema.control.robot_defaults import reaching_defaults
from bodyschema.errors import must_be
from bodyschema.evaluation.core.mlflow_log import table_metrics
from bodyschema.evaluation.core.publish import publish
from bodyschema.evaluation.core.runs import new_run
from bodyschema.evaluation.core.specs import resolve_models
from bodyschema.evaluation.core.tables import markdown_table, write_csv
from bodyschema.evaluation.reaching import report as reaching_report
from bodyschema.evaluation.reaching.benchmark import ReachingConfig, ReachingRunConfig, simulate
from bodyschema.evaluation.reaching.goals import builtin_sensors
from bodyschema.evaluation.robustness.units import noise_label

COLUMNS = ("success", "goal_success", "ee_err_mm", "ee_err_median_mm", "time_to_reach_s", "failed")


@dataclass(frozen=True)
class LoopRobustnessConfig(ReachingRunConfig):
    """Sweep observation noise on one modality and break each sensor in turn, in the closed reaching loop."""

    out: Path = Path("results/loop_robustness")      # runs go to <out>/<run-id>/, <out>/latest
    experiment: str = "bodyschema-loop-robustness"   # the MLflow experiment
    trials: int = 30                                           # reaching targets per case (AIF only)
    modality: str = "joints"                                   # the modality the noise is added to
    sigmas: tuple[float, ...] = (0.0, 0.002, 0.005, 0.01, 0.02, 0.05)   # σ in that modality's unit (rad: joints)
    broken: bool = True                                        # also run each sensor at precision 0 / frozen

    def __post_init__(self):
        super().__post_init__()
        if not self.sigmas or any(not s >= 0 for s in self.sigmas):
            raise ValueError(must_be("sigmas", "a non-empty tuple of standard deviations ≥ 0", self.sigmas))

    def reaching(self, **changes) -> ReachingConfig:
        """The reaching config of one case: the shared fields, AIF only, nothing written."""
        shared = {f.name: getattr(self, f.name) for f in fields(ReachingRunConfig)}
        return ReachingConfig(**{**shared, "baseline": False, "mlflow": False, "progress": False, **changes})


def run_loop_robustness(config: LoopRobustnessConfig = LoopRobustnessConfig(), models=None) -> dict[str, Path]:
    base = config.reaching()
    models = resolve_models(base.models, base.default_models, base.tracking_uri, models)
    from bodyschema.datagen.body.robot import Robot
    robot = Robot.load(base.robot, actuators=reaching_defaults(base.robot).actuators)
    names = [m.modality for m in models] + builtin_sensors(robot)
    if config.modality not in names:
        raise ValueError(must_be("modality", f"one of the sensed modalities {names}", config.modality))
    cases = [({"modality": config.modality, "sigma": float(s)}, replace(base, noise=((config.modality, float(s)),)))
             for s in config.sigmas]
    if config.broken:
        cases.append(({"case": "none"}, base))
        for name in dict.fromkeys(names):
            if name not in builtin_sensors(robot):                         # the AIC's encoder has no override
                cases.append(({"case": f"{name}: precision 0"}, replace(base, broken=(name,))))
            cases.append(({"case": f"{name}: frozen"}, replace(base, frozen=(name,))))
    from tqdm import tqdm
    rows = [{**key, **_row(cfg, models)} for key, cfg in tqdm(cases, desc="loop robustness",
                                                               disable=not config.progress)]
    noise, broken = rows[:len(config.sigmas)], rows[len(config.sigmas):]
    return _write(config, models, noise, broken)


def _row(config: ReachingConfig, models) -> dict:
    robot, models, modality, episodes, results, walls = simulate(config, models)
    rows = reaching_report.episode_rows(config, robot, modality, episodes, "aif", results["aif"])
    row = reaching_report.summarize(rows, walls)[0]
    return {k: row[k] for k in COLUMNS}


def _write(config: LoopRobustnessConfig, models, noise, broken) -> dict[str, Path]:
    out = new_run(config)
    paths = {"noise_csv": write_csv(noise, out / "noise_sweep.csv"),
             "noise_png": plot_noise(noise, out / "noise_sweep.png")}
    if broken:
        paths["broken_csv"] = write_csv(broken, out / "broken_sensor.csv")
        paths["broken_png"] = plot_broken(broken, out / "broken_sensor.png")
    summary = [{"case": f"{r['modality']} σ={r['sigma']:g}", **{k: r[k] for k in COLUMNS}} for r in noise] + broken
    paths["summary_csv"] = write_csv(summary, out / "summary.csv")
    paths["summary_md"] = out / "summary.md"
    paths["summary_md"].write_text(_markdown(summary, config))
    publish(config, out, "loop-robustness", table_metrics(summary, "case"), paths, models)
    return paths


def _markdown(rows, config: LoopRobustnessConfig) -> str:
    unit = modalities.unit(config.modality, "its unit")
    text = (f"Closed-loop AIF reaching on {config.robot} ({config.trials} targets, {config.seconds:g} s at "
            f"{config.rate:g} Hz, seed {config.seed}) with Gaussian noise σ on {config.modality} ({unit}) and with "
            "each sensor broken: precision 0 (the controller ignores it) or its stream frozen at the first reading "
            f"(it trusts a stale value). `success`: final ee error < {config.success_mm:g} mm; `goal_success`: "
            "within the goal tolerance.")
    return markdown_table(rows, COLUMNS, "case") + "\n" + text + "\n"


def plot_noise(rows, path: Path) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(5, 3.5))
    sigma = [r["sigma"] for r in rows]
    ax.plot(sigma, [r["success"] for r in rows], "o-", label="success (ee)")
    ax.plot(sigma, [r["goal_success"] for r in rows], "s--", label="goal success")
    ax.set(xlabel=noise_label(rows[0]["modality"]), ylabel="success rate (fraction of trials)", ylim=(-0.05, 1.05))
    if len(sigma) > 1 and min(s for s in sigma if s > 0) > 0 and sigma[0] == 0:
        ax.set_xscale("symlog", linthresh=min(s for s in sigma if s > 0))
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def plot_broken(rows, path: Path) -> Path:
    from bodyschema.evaluation.core.plots import plt, save_figure  # matplotlib only when plotting
    fig, ax = plt.subplots(figsize=(1.5 + 1.1 * len(rows), 3.8))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["success"] for r in rows], 0.4, label="success (ee)")
    ax.bar(x + 0.2, [r["goal_success"] for r in rows], 0.4, label="goal success")
    ax.set_xticks(x, [r["case"] for r in rows], rotation=30, ha="right", fontsize=8)
    ax.set(ylabel="success rate", ylim=(0, 1.05))
    ax.legend(fontsize=8)
    return save_figure(fig, path)
