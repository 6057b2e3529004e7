"""Robustness of closed-loop reaching: AIF success rate vs observation noise on one modality, and with each sensor
broken — its precision set to 0 (the controller knows) or its stream frozen at its first reading (it does not).

Every case reruns the reaching benchmark (evaluation/reaching.py) on the same targets and start poses, AIF only,
and keeps its summary row. Writes `noise_sweep.csv/png`, `broken_sensor.csv/png`, `summary.md`, `summary.csv`
and, when `mlflow` is on, one MLflow run with them as artifacts.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from bodyschema.errors import must_be
from bodyschema.evaluation import reaching_report
from bodyschema.evaluation.mlflow_log import log_benchmark, table_metrics
from bodyschema.evaluation.level_report import write_csv
from bodyschema.evaluation.levels import resolve_models
from bodyschema.evaluation.reaching import ReachingConfig, simulate

COLUMNS = ("success", "goal_success", "ee_err_mm", "ee_err_median_mm", "time_to_reach_s", "failed")


@dataclass(frozen=True)
class LoopRobustnessConfig:
    """Sweep observation noise on one modality and break each sensor in turn, in the closed reaching loop."""

    reaching: ReachingConfig = field(default_factory=lambda: ReachingConfig(targets=30, baseline=False,
                                                                            mlflow=False))  # robot, models, seed
    modality: str = "joints"                                   # the modality the noise is added to
    sigmas: tuple[float, ...] = (0.0, 0.002, 0.005, 0.01, 0.02, 0.05)   # σ in that modality's unit (rad: joints)
    broken: bool = True                                        # also run each sensor at precision 0 / frozen
    out: Path = Path("results/loop_robustness")
    mlflow: bool = True
    experiment: str = "bodyschema-loop-robustness"

    def __post_init__(self):
        if not self.sigmas or any(not s >= 0 for s in self.sigmas):
            raise ValueError(must_be("sigmas", "a non-empty tuple of standard deviations ≥ 0", self.sigmas))


def run_loop_robustness(config: LoopRobustnessConfig = LoopRobustnessConfig(), models=None) -> dict[str, Path]:
    base = replace(config.reaching, baseline=False, mlflow=False, noise=(), broken=(), frozen=())
    models = resolve_models(base.models, base.default_models, base.tracking_uri, models)
    names = [m.modality for m in models] + (["joints"] if base.robot == "panda" else [])
    if config.modality not in names:
        raise ValueError(must_be("modality", f"one of the sensed modalities {names}", config.modality))
    cases = [({"modality": config.modality, "sigma": float(s)}, replace(base, noise=((config.modality, float(s)),)))
             for s in config.sigmas]
    if config.broken:
        cases.append(({"case": "none"}, base))
        for name in dict.fromkeys(names):
            if not (base.robot == "panda" and name == "joints"):           # the AIC's encoder has no override
                cases.append(({"case": f"{name}: precision 0"}, replace(base, broken=(name,))))
            cases.append(({"case": f"{name}: frozen"}, replace(base, frozen=(name,))))
    from tqdm import tqdm
    rows = [{**key, **_row(replace(cfg, progress=False), models)}
            for key, cfg in tqdm(cases, desc="loop robustness", disable=not base.progress)]
    noise, broken = rows[:len(config.sigmas)], rows[len(config.sigmas):]
    return _write(config, base, models, noise, broken)


def _row(config: ReachingConfig, models) -> dict:
    robot, models, modality, episodes, results, walls = simulate(config, models)
    rows = reaching_report.episode_rows(config, robot, modality, episodes, "aif", results["aif"])
    row = reaching_report.summarize(rows, walls)[0]
    return {k: row[k] for k in COLUMNS}


def _write(config: LoopRobustnessConfig, base: ReachingConfig, models, noise, broken) -> dict[str, Path]:
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"noise_csv": write_csv(noise, out / "noise_sweep.csv"),
             "noise_png": plot_noise(noise, out / "noise_sweep.png")}
    if broken:
        paths["broken_csv"] = write_csv(broken, out / "broken_sensor.csv")
        paths["broken_png"] = plot_broken(broken, out / "broken_sensor.png")
    summary = [{"case": f"{r['modality']} σ={r['sigma']:g}", **{k: r[k] for k in COLUMNS}} for r in noise] + broken
    paths["summary_csv"] = write_csv(summary, out / "summary.csv")
    paths["summary_md"] = out / "summary.md"
    paths["summary_md"].write_text(_markdown(summary, base, config))
    if config.mlflow:
        metrics = table_metrics(summary, lambda row: row["case"])
        log_benchmark(config, f"loop-robustness-{base.robot}", metrics, paths.values(), models, base.tracking_uri)
    return paths


def _markdown(rows, base: ReachingConfig, config: LoopRobustnessConfig) -> str:
    lines = ["| case | " + " | ".join(COLUMNS) + " |", "|" + "---|" * (len(COLUMNS) + 1)]
    for r in rows:
        lines.append(f"| {r['case']} | " + " | ".join(f"{r[c]:.4g}" for c in COLUMNS) + " |")
    text = (f"Closed-loop AIF reaching on {base.robot} ({base.targets} targets, {base.seconds:g} s at "
            f"{base.rate:g} Hz, "
            f"seed {base.seed}) with Gaussian noise σ on {config.modality} (its unit) and with each sensor broken: "
            "precision 0 (the controller ignores it) or its stream frozen at the first reading (it trusts a stale "
            f"value). `success`: final ee error < {base.success_mm:g} mm; `goal_success`: within the goal tolerance.")
    return "\n".join(lines) + "\n\n" + text + "\n"


def plot_noise(rows, path: Path) -> Path:
    from bodyschema.training.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(5, 3.5))
    sigma = [r["sigma"] for r in rows]
    ax.plot(sigma, [r["success"] for r in rows], "o-", label="success (ee)")
    ax.plot(sigma, [r["goal_success"] for r in rows], "s--", label="goal success")
    ax.set(xlabel=f"observation noise σ on {rows[0]['modality']}", ylabel="success rate", ylim=(-0.05, 1.05))
    if len(sigma) > 1 and min(s for s in sigma if s > 0) > 0 and sigma[0] == 0:
        ax.set_xscale("symlog", linthresh=min(s for s in sigma if s > 0))
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def plot_broken(rows, path: Path) -> Path:
    from bodyschema.training.plots import plt, save_figure
    fig, ax = plt.subplots(figsize=(1.5 + 1.1 * len(rows), 3.8))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["success"] for r in rows], 0.4, label="success (ee)")
    ax.bar(x + 0.2, [r["goal_success"] for r in rows], 0.4, label="goal success")
    ax.set_xticks(x, [r["case"] for r in rows], rotation=30, ha="right", fontsize=8)
    ax.set(ylabel="success rate", ylim=(0, 1.05))
    ax.legend(fontsize=8)
    return save_figure(fig, path)
