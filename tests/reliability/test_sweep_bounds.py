"""Bad input to `bodyschema sweep` (issue 32, item 12): refused with the house line before Ray starts or any run is
made — a trial whose fit cannot fit in memory (train's guard, run on every trial), more trials than MAX_TRIALS, a
grid value given twice, a list flag given twice (the parser kept the last only), --max-concurrent 0, --random -1
(named as --random). A kill -9 of a sweep leaves no Ray process behind (slow)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from bodyschema.models.configs import MDNConfig
from bodyschema.training.sweep_space import MAX_TRIALS, parse_space
from tests.test_cli_fuzz import run_and_check

SWEEP = "sweep mdn --data {W}/good.zarr --no-progress "
THOUSAND = ",".join(str(k) for k in range(1, 1001))
CASES = [
    ("sweep-trial-too-big-for-memory", SWEEP + "--grid hidden=100000x100000x100000"),
    ("sweep-one-trial-of-a-grid-too-big", SWEEP + "--grid hidden=64x64,100000x100000x100000"),
    ("sweep-1000x1000-grid", SWEEP + f"--grid batch_size={THOUSAND} n_components={THOUSAND}"),
    ("sweep-random-draws-unbounded", SWEEP + "--random 100000 --space lr=1e-4:1e-2:log"),
    ("sweep-grid-value-twice", SWEEP + "--grid lr=1e-3,1e-3"),
    ("sweep-grid-flag-twice", SWEEP + "--grid lr=1e-3 --grid lr=2e-3"),
    ("sweep-space-flag-twice", SWEEP + "--random 2 --space lr=1e-4:1e-2 --space batch_size=8:64"),
    ("sweep-max-concurrent-0", SWEEP + "--grid lr=1e-3 --max-concurrent 0"),
    ("sweep-random-negative", SWEEP + "--random -1"),
]


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    return make_world(tmp_path_factory.mktemp("sweep_bounds"))


def make_world(w):
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    generate(DatagenConfig(robot="planar2", n=64, images=False, out=w / "good.zarr"), progress=False)
    return w


@pytest.mark.parametrize("case_id, command", CASES, ids=[c[0] for c in CASES])
def test_bad_sweep_is_a_clear_error_before_ray(case_id, command, in_world, capsys, monkeypatch):
    import ray

    monkeypatch.setattr(ray, "init", _no_ray)                # every case is refused before Ray would start
    err = run_and_check(case_id, command, in_world, capsys)
    assert not (in_world / "runs").exists(), "no sweep folder"
    assert "mlartifacts" not in os.listdir(in_world), "no MLflow run"
    if case_id == "sweep-random-negative":
        line = err.strip().splitlines()[-1]
        assert "--random must be a count ≥ 0" in line and "--space" not in err, err
    if "memory" in case_id or "too-big" in case_id:
        assert "network fit memory must be at most" in err and "sweep trial hidden=100000x100000x100000" in err, err
    if "1000x1000" in case_id or "unbounded" in case_id:
        assert f"at most {MAX_TRIALS:,}" in err, err
    if "flag-twice" in case_id:
        assert "given once" in err, err


def _no_ray(*args, **kwargs):
    raise AssertionError("Ray started for a sweep that should have been refused")


def test_the_trial_bound_counts_grid_points_times_draws():
    assert parse_space(MDNConfig, "mdn", (f"batch_size={THOUSAND}",), (), 0).trials == MAX_TRIALS    # at the bound
    with pytest.raises(ValueError, match="number of trials"):
        parse_space(MDNConfig, "mdn", ("batch_size=8,16",), ("lr=1e-4:1e-2",), MAX_TRIALS // 2 + 1)


def test_every_grid_point_is_checked_with_random_dimensions_at_their_high_end():
    space = parse_space(MDNConfig, "mdn", ("hidden=8x8,16", "lr=1e-3,2e-3"), ("n_components=2:9",), 2)
    points = list(space.points())
    assert len(points) == 4 and all(p["n_components"] == 9 for p in points)
    assert {(p["hidden"], p["lr"]) for p in points} == {((8, 8), 1e-3), ((8, 8), 2e-3), ((16,), 1e-3), ((16,), 2e-3)}


def test_a_good_grid_still_passes_the_memory_check(in_world, capsys):
    """The guard refuses only what does not fit: the same store and a small grid pass it (the plan is made, Ray not
    started: --max-concurrent above the CPUs is refused right after)."""
    from bodyschema.training.data import load_dataset
    from bodyschema.training.sweep import check_memory, plan
    from bodyschema.training.sweep_config import SweepConfig

    p = plan(SweepConfig("mdn", in_world / "good.zarr", grid=("hidden=64x64,128x128",)))
    data = load_dataset(p.train.data, p.train.modalities, val_fraction=p.train.val_fraction, seed=p.train.seed)
    check_memory(p, data)
    with pytest.raises(ValueError, match="sweep trial hidden=128x128"):
        check_memory(p, data, available=1e6)                 # 0.8 MB: the second point named when it does not fit


@pytest.mark.slow
def test_a_killed_sweep_leaves_no_ray_process(in_world):
    """kill -9 of the driver mid-sweep: every process it started (GCS, raylet, dashboard, agents, workers) is gone
    within seconds (it used to take one to two minutes, an agent listening on loopback)."""
    command = [sys.executable, "-m", "bodyschema.cli", *(SWEEP.format(W=in_world).split()), "--no-register",
               "--grid", "patience=100000", "lr=6e-4", "--epochs-budget", "100000"]
    driver = subprocess.Popen(command, cwd=in_world, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not any("ImplicitFunc" in c for c in _tree(driver.pid).values()):
            assert driver.poll() is None, "the sweep ended before it could be killed"
            time.sleep(0.5)
        started = _tree(driver.pid)
        assert any("raylet" in c for c in started.values()), started
    finally:
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait()
    deadline = time.time() + 15
    while time.time() < deadline and _alive(started):
        time.sleep(0.5)
    assert not _alive(started), f"Ray processes outlived their driver: {_alive(started)}"


def _tree(root: int) -> dict[int, str]:
    """pid → command line of every descendant of `root`."""
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,ppid=,args="], capture_output=True, text=True).stdout
    rows = [line.split(None, 2) for line in out.splitlines() if len(line.split(None, 2)) == 3]
    found, todo = {}, [root]
    while todo:
        pid = todo.pop()
        for child, parent, args in rows:
            if int(parent) == pid and int(child) not in found:
                found[int(child)] = args
                todo.append(int(child))
    return found


def _alive(processes: dict[int, str]) -> dict[int, str]:
    alive = {}
    for pid, args in processes.items():
        try:
            state = open(f"/proc/{pid}/stat").read().rpartition(")")[2].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive[pid] = args
    return alive
