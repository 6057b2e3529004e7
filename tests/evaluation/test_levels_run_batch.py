"""Several levels runs in one batch (`run_batch`): each run's rows as when it runs alone, and the batching rule."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels
from bodyschema.evaluation.levels.run_batch import RunBatch, chunks, runs_per_batch
from bodyschema.evaluation.levels.targets import Targets
from bodyschema.models.analytic import AnalyticModel
from tests.evaluation.test_levels_recorded import tiny_decoder  # noqa: F401 — a fixture, by name

# What a run's row may differ by between a batch of one run and a batch of three: a float64 model's arithmetic is the
# same row by row, but batched kernels may block a larger batch differently (measured 1e-10 rad on nao_arm); 1e-6
# leaves room for a step control that decides a float apart, far below any figure the tables print (0.01).
ROUNDING = 1e-6
SHARED = ("wall_s", "evaluations_per_trial")        # the batch's, shared by trials: not a run's own


@pytest.fixture(scope="module")
def nao_xyz():
    return AnalyticModel("nao_arm", "ee_xyz")


def test_each_runs_rows_in_one_batch_are_its_rows_alone(tmp_path, nao_xyz):
    config = LevelsConfig(trials=12, runs=3, multistart=3, screen_steps=2, mlflow=False, plots=False, out=tmp_path,
                          progress=False)
    alone, curves_alone = measure_levels(replace(config, run_batch=1), [nao_xyz])
    together, curves_together = measure_levels(replace(config, run_batch=3), [nao_xyz])
    pairs = list(zip(alone.floor_rows + alone.rows, together.floor_rows + together.rows))
    assert [(a["run"], a["level"]) for a, _ in pairs] == [(b["run"], b["level"]) for _, b in pairs]
    assert len(pairs) == 3 * 5                                           # floor, levels 1, 2, 3, 3+ms per run
    for a, b in pairs:
        assert a.keys() == b.keys()
        for key in a.keys() - {"level", *SHARED}:
            assert b[key] == pytest.approx(a[key], rel=ROUNDING, abs=ROUNDING), (a["run"], a["level"], key)
    assert curves_alone.keys() == curves_together.keys() == {"1", "2", "3"}
    for level, curve in curves_alone.items():                            # run 0's columns only
        assert curves_together[level].shape[1] == curve.shape[1] == config.trials
        np.testing.assert_allclose(curves_together[level][:len(curve)], curve, rtol=ROUNDING)


def test_a_batch_splits_into_its_runs_targets():
    parts = [Targets(np.full((n, 2), float(n)), {"ee_xyz": np.full((n, 3), -float(n))}) for n in (2, 5, 1)]
    batch = RunBatch.of(parts)
    assert batch.targets.q.shape == (8, 2) and batch.sizes == (2, 5, 1)
    for i, part in enumerate(parts):
        np.testing.assert_array_equal(batch.part(i).q, part.q)
        np.testing.assert_array_equal(batch.part(i).observations["ee_xyz"], part.observations["ee_xyz"])


@pytest.mark.parametrize(("runs", "workers", "per_batch", "expected"), [
    (5, 1, 0, [(0, 1, 2, 3, 4)]),
    (5, 2, 0, [(0, 1, 2), (3, 4)]),
    (5, 1, 2, [(0, 1), (2, 3), (4,)]),
    (5, 3, 1, [(0,), (1,), (2,), (3,), (4,)]),
    (1, 4, 0, [(0,)]),
])
def test_runs_are_cut_into_consecutive_batches_per_worker(runs, workers, per_batch, expected):
    assert chunks(runs, workers, per_batch) == expected


def test_the_rule_keeps_image_models_on_the_cpu_one_run_per_batch(nao_xyz, tiny_decoder):  # noqa: F811
    assert runs_per_batch(0, [nao_xyz], None, "cpu") == 0                # all of a worker's runs
    assert runs_per_batch(0, [tiny_decoder], None, "cpu") == 1           # measured slower in a larger batch
    assert runs_per_batch(0, [nao_xyz], object(), "cpu") == 1            # an image encoder counts as an image
    assert runs_per_batch(0, [tiny_decoder], None, "cuda:0") == 0        # a GPU fills with the larger batch
    assert runs_per_batch(2, [tiny_decoder], None, "cpu") == 2           # the user's setting wins


def test_a_run_batch_out_of_its_bounds_is_the_house_error():
    with pytest.raises(ValueError, match=r"run_batch must be at least 0. Got -1"):
        LevelsConfig(run_batch=-1)
    with pytest.raises(ValueError, match=r"run_batch must be at most 100. Got 101. Runs inferred in one batch"):
        LevelsConfig(run_batch=101)
