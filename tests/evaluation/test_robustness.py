"""`evaluate robustness`: error grows with observation noise, a broken sensor is survived when another remains,
and every table and plot is written."""

import csv
import math

from bodyschema.aif.perception import PerceptionConfig
from bodyschema.evaluation.robustness.perception import RobustnessConfig, run_robustness
from bodyschema.models.analytic import AnalyticModel


def test_robustness_writes_noise_and_broken_sensor_tables_and_plots(tmp_path):
    models = [AnalyticModel("planar2", "ee_xyz"), AnalyticModel("planar2", "joints")]
    perception = PerceptionConfig(precisions=(("ee_xyz", 1e-3 ** -2), ("joints", math.radians(1.0) ** -2)))
    config = RobustnessConfig(trials=20, runs=1, mlflow=False, perception=perception, modality="ee_xyz",
                              sigmas=(0.0, 0.003, 0.03), out=tmp_path)
    paths = run_robustness(config, models=models)
    assert all(p.stat().st_size > 0 for p in paths.values())
    noise = list(csv.DictReader(paths["noise_csv"].open()))
    errors = [float(r["joint_err_deg"]) for r in noise]
    assert errors[0] < errors[-1], f"joint error must grow with ee_xyz noise: {errors}"
    broken = {r["broken"]: float(r["joint_err_deg"]) for r in csv.DictReader(paths["broken_csv"].open())}
    assert set(broken) == {"none", "ee_xyz", "joints"}
    summary = paths["summary_md"].read_text()                             # one row per σ and per broken sensor
    assert all(f"| {float(s)} |" in summary for s in config.sigmas) and all(f"| {b} |" in summary for b in broken)


def test_the_noise_plots_name_the_unit_of_sigma(tmp_path, monkeypatch):
    """noise_sweep.png (perception and closed loop): σ in the modality's unit on the x axis, the error's unit on y."""
    import bodyschema.evaluation.core.plots as core_plots
    from bodyschema.evaluation.robustness.loop import plot_noise

    labels = {}
    save = core_plots.save_figure

    def recording(fig, path, **kw):
        labels[path.name] = (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel())
        return save(fig, path, **kw)
    monkeypatch.setattr(core_plots, "save_figure", recording)

    models = [AnalyticModel("planar2", "ee_pixel"), AnalyticModel("planar2", "joints")]
    run_robustness(RobustnessConfig(trials=4, mlflow=False, progress=False, modality="ee_pixel", sigmas=(0.0, 1.0),
                                    out=tmp_path / "open"), models=models)
    assert labels["noise_sweep.png"] == ("observation noise σ on ee_pixel (px)",
                                         "joint error after perception (deg, mean over joints and trials)")
    rows = [{"modality": "joints", "sigma": s, "success": 1.0, "goal_success": 1.0} for s in (0.0, 0.01)]
    plot_noise(rows, tmp_path / "loop" / "noise_sweep.png")
    assert labels["noise_sweep.png"][0] == "observation noise σ on joints (rad)"
