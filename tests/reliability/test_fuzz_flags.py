"""The fuzz test of tests/test_cli_fuzz.py extended to the bounds of the evaluate / train / demo flags (issue 25):
unbounded counts and durations, NaN / infinite / negative numbers, duplicate modalities, a network larger than memory,
a demo flag used only minutes in. Each case must end as a clear error (exit 2, a house line, no traceback) with not
one file of the scratch folder added, removed or changed. Adding a case is one line in CASES."""

from __future__ import annotations

import sqlite3

import pytest

from bodyschema import cli
from tests.test_cli_fuzz import build_world, run_and_check, run_in_process

CASES = [   # (id, argv; {W} is the scratch folder of build_world: good.zarr kinematics, img.zarr images)
    ("levels-runs-huge", "evaluate levels --runs 1000000000 --out {W}/res"),
    ("levels-trials-huge", "evaluate levels --trials 1000000 --out {W}/res"),
    ("levels-max-steps-huge", "evaluate levels --perception.max-steps 1000000000 --out {W}/res"),
    ("levels-multistart-huge", "evaluate levels --multistart 100000 --out {W}/res"),
    ("levels-success-deg-nan", "evaluate levels --success-deg nan --out {W}/res"),
    ("levels-success-deg-inf", "evaluate levels --success-deg inf --out {W}/res"),
    ("levels-noise-inf", "evaluate levels --noise ee_pixel inf --out {W}/res"),
    ("levels-perception-dt-inf", "evaluate levels --perception.dt inf --out {W}/res"),
    ("robustness-noise-inf", "evaluate robustness --noise ee_pixel inf --out {W}/res"),
    ("robustness-sigmas-inf", "evaluate robustness --sigmas inf --out {W}/res"),
    ("robustness-runs-huge", "evaluate robustness --runs 1000000 --out {W}/res"),
    ("robustness-level-7", "evaluate robustness --level 7 --out {W}/res"),
    ("levels-image-size-huge", "evaluate levels --image-size 100000 100000 --trials 2 --runs 1 --out {W}/res"),
    ("reaching-duration-huge", "evaluate reaching --duration 1e9 --out {W}/res"),
    ("reaching-duration-nan", "evaluate reaching --duration nan --out {W}/res"),
    ("reaching-success-mm-negative", "evaluate reaching --success-mm -1 --out {W}/res"),
    ("reaching-noise-inf", "evaluate reaching --noise ee_pixel inf --out {W}/res"),
    ("reaching-goal-starts-huge", "evaluate reaching --goal-starts 1000000 --out {W}/res"),
    ("reaching-depth-cue-inf", "evaluate reaching --depth-cue-deg inf --out {W}/res"),
    ("reaching-action-gain-inf", "evaluate reaching --action.k-a inf --out {W}/res"),
    ("loop-robustness-trials-huge", "evaluate loop-robustness --trials 100000000 --out {W}/res"),
    ("loop-robustness-sigmas-inf", "evaluate loop-robustness --sigmas 0 inf --out {W}/res"),
    ("marker-shift-duration-inf", "evaluate adaptation marker-shift --duration inf --out {W}/res"),
    ("marker-shift-offset-nan", "evaluate adaptation marker-shift --offset nan --out {W}/res"),
    ("jupiter-duration-huge", "evaluate adaptation jupiter --duration 1e9 --out {W}/res"),
    ("jupiter-gravity-nan", "evaluate adaptation jupiter --jupiter-gravity nan --out {W}/res"),
    ("jupiter-aic-precision-inf", "evaluate adaptation jupiter --aic.precisions ee_xyz inf --out {W}/res"),
    ("self-recognition-steps-huge", "evaluate self-recognition --steps 100000000 --out {W}/res"),
    ("self-recognition-period-huge", "evaluate self-recognition --period 1e9 --out {W}/res"),
    ("self-recognition-noise-inf", "evaluate self-recognition --proprio-noise inf --out {W}/res"),
    ("rubber-hand-period-tiny", "evaluate rubber-hand --period 1e-9 --out {W}/res"),
    ("rubber-hand-strokes-huge", "evaluate rubber-hand --stroke-rate-hz 1e9 --stroke-jitter-s 0 --out {W}/res"),
    ("rubber-hand-duration-huge", "evaluate rubber-hand --duration 1e9 --out {W}/res"),
    ("agency-steps-huge", "evaluate agency --steps 100000000 --out {W}/res"),
    ("agency-period-huge", "evaluate agency --period 1e9 --out {W}/res"),
    ("agency-visual-noise-nan", "evaluate agency --visual-noise ee_pixel nan --out {W}/res"),
    ("train-multimodal-duplicate", "train multimodal --modality ee_xyz,ee_xyz --data {W}/img.zarr"),
    ("train-pixel-channels-huge", "train pixel --channels 100000 100000 --data {W}/img.zarr"),
    ("train-mdn-hidden-huge", "train mdn --hidden 1000000 1000000 --data {W}/good.zarr"),
    ("train-pixel-epochs-0", "train pixel --epochs 0 --data {W}/img.zarr"),
    ("demo-episodes-1", "demo --episodes 1 --out {W}/demo"),
    ("demo-runs-huge", "demo --runs 1000 --out {W}/demo"),
    ("demo-trials-huge", "demo --trials 100000 --out {W}/demo"),
    ("demo-reach-targets-0", "demo --reach-targets 0 --out {W}/demo"),
    ("demo-pixel-epochs-0", "demo --pixel-epochs 0 --out {W}/demo"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return build_world(tmp_path_factory.mktemp("fuzz_flags"))


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_a_bad_flag_is_a_clear_error(case_id, command, in_world, capsys):
    err = run_and_check(case_id, command, in_world, capsys)
    assert "dtype" not in err, f"{case_id}: the error names a dtype instead of the value:\n{err}"


def test_a_network_too_large_is_refused_before_an_mlflow_run_exists(in_world, capsys):
    code, err = run_in_process(f"train pixel --channels 100000 100000 --data {in_world}/img.zarr".split(), capsys)
    assert code == 2 and "network fit memory must be at most" in err
    with sqlite3.connect(in_world / "mlflow.db") as db:
        assert db.execute("select count(*) from runs").fetchone()[0] == 0, "no MLflow run is left behind"


@pytest.mark.parametrize("argv, resumes", [(["evaluate", "levels"], False), (["evaluate", "reaching"], False),
                                           (["datagen"], True), (["demo"], True)])
def test_after_ctrl_c_the_message_says_whether_the_command_resumes(argv, resumes, monkeypatch, capsys):
    monkeypatch.setattr(cli, "run", lambda *args: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert cli.main(argv) == 130
    assert ("resume" in capsys.readouterr().err) is resumes
