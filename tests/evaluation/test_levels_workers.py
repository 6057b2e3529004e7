"""Levels runs spread over worker processes (`--workers`): the rows of one process, or the house error."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bodyschema.evaluation.levels.benchmark import LevelsConfig, measure_levels
from bodyschema.models.analytic import AnalyticModel
from tests.evaluation.test_levels_recorded import tiny_decoder  # noqa: F401 — a fixture, by name
from tests.threads import one_thread


class Forgetful(AnalyticModel):
    """planar2's hand, moved by `shift` m, which pickling forgets (as a model whose state lives outside Python)."""

    shift = 0.0

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "shift"}

    def _predict(self, z):
        return super()._predict(z) + self.shift


def test_runs_over_worker_processes_give_the_rows_of_one_process(tmp_path, tiny_decoder):  # noqa: F811
    config = LevelsConfig(levels=(1, 3), trials=4, runs=3, multistart=2, screen_steps=2, mlflow=False, plots=False,
                          out=tmp_path, perception=replace(LevelsConfig().perception, max_steps=20))
    with one_thread():
        one, curves = measure_levels(config, [tiny_decoder])
    two, curves_two = measure_levels(replace(config, workers=2), [tiny_decoder])
    assert [(r["run"], r["level"]) for r in two.rows] == [(r["run"], r["level"]) for r in one.rows]
    for a, b in zip(one.rows, two.rows):
        assert {k: v for k, v in a.items() if k != "wall_s"} == {k: v for k, v in b.items() if k != "wall_s"}
    assert curves.keys() == curves_two.keys() == {"1", "3"}
    np.testing.assert_array_equal(curves["1"], curves_two["1"])


def test_a_model_that_pickling_changes_is_the_house_error_not_wrong_rows(tmp_path):
    model = Forgetful("planar2", "ee_xyz")
    model.shift = 0.01
    config = LevelsConfig(levels=(1,), trials=3, runs=2, multistart=0, workers=2, mlflow=False, plots=False,
                          out=tmp_path)
    with pytest.raises(ValueError, match="the same after pickling"):
        measure_levels(config, [model])
