"""Closed-loop robustness sweeps on nao_arm: noise and broken sensors change what the controller can do."""

import csv

import pytest

from bodyschema.evaluation.robustness.loop import LoopRobustnessConfig, run_loop_robustness

REACHING = {"trials": 3, "duration": 1.5, "progress": False}      # flat flags: --trials, --duration


def read_rows(path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def test_sweeps_write_tables_and_a_dead_encoder_stops_the_arm(tmp_path):
    paths = run_loop_robustness(LoopRobustnessConfig(**REACHING, sigmas=(0.0, 0.01), out=tmp_path, mlflow=False))
    for key in ("noise_csv", "noise_png", "broken_csv", "broken_png", "summary_csv", "summary_md"):
        assert paths[key].is_file() and paths[key].stat().st_size > 0
    noise = read_rows(paths["noise_csv"])
    assert [float(r["sigma"]) for r in noise] == [0.0, 0.01]
    broken = {r["case"]: r for r in read_rows(paths["broken_csv"])}
    assert set(broken) == {"none", "ee_pixel: precision 0", "ee_pixel: frozen", "joints: precision 0",
                           "joints: frozen"}
    # σ = 0 reruns the intact case exactly; only the joint encoder drives action, so without it nothing reaches
    assert noise[0]["goal_success"] == broken["none"]["goal_success"] and float(noise[0]["goal_success"]) > 0
    assert float(broken["joints: precision 0"]["goal_success"]) == 0.0
    assert float(broken["joints: precision 0"]["ee_err_mm"]) > float(broken["none"]["ee_err_mm"])


def test_bad_config_raises():
    with pytest.raises(ValueError, match="sigmas"):
        LoopRobustnessConfig(sigmas=(-1.0,))
    with pytest.raises(ValueError, match="modality"):
        run_loop_robustness(LoopRobustnessConfig(**REACHING, modality="image", mlflow=False))
