"""`bodyschema sweep KIND`: the search space read with the kind's types, bad input refused before any run, ASHA for
networks (FIFO for a GP), and, with a local Ray (slow), a parent run with one child per trial, the best registered,
`@champion` moved only when better, and a re-run that continues the same sweep instead of redoing it."""

from __future__ import annotations

import dataclasses

import pytest

from bodyschema.cli import main
from bodyschema.models.configs import MDNConfig, PixelConfig
from bodyschema.training.sweep_config import SweepConfig
from bodyschema.training.sweep_space import parse_space

# The README's `make test` installs the test extra, which holds ray; a hand-made venv without it skips, saying why.
RAY_EXTRA = "the sweep runs on Ray Tune: pip install -e '.[ray]' (the test extra includes it)"


def test_space_values_are_read_with_the_kinds_own_types():
    space = parse_space(PixelConfig, "pixel", ("lr=1e-3,3e-3", "channels=16x8,32x16", "precision=none,50"),
                        ("batch_size=16:64:log",), 3)
    grid = {d.name: d.grid for d in space.dimensions if d.grid}
    assert grid == {"lr": (1e-3, 3e-3), "channels": ((16, 8), (32, 16)), "precision": (None, 50.0)}
    assert space.trials == 3 * 2 * 2 * 2                       # draws per grid point × grid points
    assert space.first() == {"lr": 1e-3, "channels": (16, 8), "precision": None, "batch_size": 16}
    PixelConfig(**space.first())                               # the probe's configuration is a valid one


@pytest.mark.parametrize("grid, space, random, says", [
    (("hiden=8",), (), 0, "one of ['hidden', 'n_components'"),        # unknown name: the valid ones listed
    (("lr=fast",), (), 0, "--grid lr must be a finite number"),        # wrong type
    (("mode=median",), (), 0, "one of ['mean', 'max']"),
    (("epochs=0",), (), 0, "an integer ≥ 1"),                          # the config's own bound (COUNTS)
    (("hidden=8,16x",), (), 0, "widths joined by x"),
    (("lr=",), (), 0, "at least one value"),                           # an empty grid
    ((), (), 0, "non-empty --grid"),                                   # no search space at all
    ((), ("lr=1e-2:1e-3",), 2, "lo < hi"),
    ((), ("mode=1:2",), 2, "int or float hyper-parameter"),
    ((), ("lr=1e-3:1e-2",), 0, "--random must be ≥ 1"),
    (("lr=1e-3", "lr=2e-3"), (), 0, "named once"),
])
def test_bad_search_spaces_name_the_flag(grid, space, random, says):
    with pytest.raises(ValueError, match=None) as caught:
        parse_space(MDNConfig, "mdn", grid, space, random)
    assert says in str(caught.value)


def test_bad_input_is_refused_before_any_run(kin_store, workdir, monkeypatch):
    """Each bad input: the house error (exit 2 from the CLI), no MLflow run, nothing registered, no sweep folder."""
    import os

    pytest.importorskip("ray", reason=RAY_EXTRA)

    from mlflow import MlflowClient

    from bodyschema.training.sweep import sweep

    base = ["sweep", "mdn", "--data", str(kin_store), "--no-progress"]
    cpus = os.cpu_count() or 1
    for extra in (["--grid", "hiden=8"], ["--grid", "lr=fast"], ["--grid", "lr="], [],
                  ["--grid", "lr=1e-3", "--max-concurrent", str(cpus + 1)], ["--grid", "lr=1e-3", "--epochs-budget",
                                                                            "2", "--space", "epochs=1:3", "--random",
                                                                            "1"]):
        assert main(base + extra) == 2, extra
    with pytest.raises(ValueError, match="KIND must be one of"):
        sweep(SweepConfig("encoder", kin_store, grid=("lr=1e-3",)))
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:9")                  # nothing listens on the discard port
    with pytest.raises(ConnectionError, match="RAY_ADDRESS must be a Ray cluster accepting connections"):
        sweep(SweepConfig("mdn", kin_store, grid=("lr=1e-3",), max_concurrent=1, progress=False))
    client = MlflowClient(f"sqlite:///{workdir / 'mlflow.db'}")
    assert client.search_runs([e.experiment_id for e in client.search_experiments()]) == []
    assert client.search_registered_models() == []
    assert not (workdir / "runs").exists()


def test_a_grid_of_losses_is_refused_one_loss_is_swept(kin_store):
    """ASHA ranks trials by val_loss: a cross-entropy and a squared error are not on one scale."""
    from bodyschema.training.sweep import plan

    with pytest.raises(ValueError, match=r"--grid loss must be one value. Got 'mse, cross_entropy'. ASHA compares"):
        plan(SweepConfig("pixel", kin_store, grid=("loss=mse,cross_entropy",)))
    assert plan(SweepConfig("pixel", kin_store, grid=("loss=mse", "lr=1e-3,2e-3"))).space.trials == 2


def test_networks_get_asha_per_epoch_and_a_gp_no_early_stop(kin_store):
    pytest.importorskip("ray", reason=RAY_EXTRA)
    from ray.tune.schedulers import ASHAScheduler, FIFOScheduler

    from bodyschema.training.sweep import plan, scheduler

    net = plan(SweepConfig("mdn", kin_store, grid=("lr=1e-3,3e-3",), epochs_budget=7, grace_period=2))
    asha = scheduler(net)
    assert isinstance(asha, ASHAScheduler)
    assert (asha._time_attr, asha.metric, asha._mode) == ("epoch", "val_loss", "min")
    assert asha._max_t == 8                                   # past the last epoch: a full trial is never cut
    assert sorted(r for r, _ in asha._brackets[0]._rungs) == [2, 6]      # first rung at the grace period
    gp = plan(SweepConfig("gpr", kin_store, grid=("noise_floor=1e-8,1e-6",)))
    assert not gp.network and isinstance(scheduler(gp), FIFOScheduler)


@pytest.mark.slow
def test_a_tiny_grid_on_local_ray(kin_store, workdir):
    pytest.importorskip("ray", reason=RAY_EXTRA)
    """2×2 mdn grid, 2 epochs: 4 children under one parent, the best registered and champion; the same command again
    continues the same sweep (no new run, same version); a worse grid moves champion only if its best is better."""
    from mlflow import MlflowClient

    from bodyschema.training.champion import CHAMPION
    from bodyschema.training.sweep import sweep

    config = SweepConfig("mdn", kin_store, grid=("lr=3e-3,1e-2", "batch_size=32,64"), epochs_budget=2,
                         grace_period=1, max_concurrent=2, progress=False)
    first = sweep(config)
    client = MlflowClient(f"sqlite:///{workdir / 'mlflow.db'}")
    parent = client.get_run(first.parent_run_id)
    assert parent.info.run_name == "sweep · mdn · planar2" and parent.info.status == "FINISHED"
    children = client.search_runs([parent.info.experiment_id],
                                  f"tags.mlflow.parentRunId = '{first.parent_run_id}'")
    assert len(children) == 4 == len(first.trials)
    assert {c.data.params["hyper.lr"] for c in children} == {"0.003", "0.01"}
    ended = {t.child_run_id: "FINISHED" if t.val_rmse is not None else "KILLED" for t in first.trials}
    assert {c.info.run_id: c.info.status for c in children} == ended             # none left RUNNING
    finished = [t for t in first.trials if t.val_rmse is not None]
    best = min(finished, key=lambda t: t.val_rmse)
    assert first.registered.champion
    version = client.get_model_version_by_alias(first.registered.name, CHAMPION)
    assert str(version.version) == first.registered.version
    assert float(version.tags["val_rmse"]) == best.val_rmse
    assert version.run_id == best.child_run_id

    again = sweep(config)                                    # Tuner.restore: finished trials are not rerun
    assert again.parent_run_id == first.parent_run_id
    assert again.registered.version == first.registered.version
    assert len(client.search_runs([parent.info.experiment_id], "tags.mlflow.parentRunId != ''")) == 4

    worse = sweep(dataclasses.replace(config, grid=("lr=1e-5,2e-5", "batch_size=32,64"), epochs_budget=1))
    assert worse.parent_run_id != first.parent_run_id
    better = min(t.val_rmse for t in worse.trials if t.val_rmse is not None) < best.val_rmse
    assert worse.registered.champion == better
    champion = str(client.get_model_version_by_alias(first.registered.name, CHAMPION).version)
    assert champion == (worse.registered.version if better else first.registered.version)
