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
