"""Benchmark logging helpers: nested configs flatten, only finite numbers become metrics, names are MLflow-legal."""

import math
from dataclasses import dataclass, field

from bodyschema.evaluation.core.mlflow_log import config_params, metric_name, table_metrics


@dataclass(frozen=True)
class Inner:
    gain: float = 2.0


@dataclass(frozen=True)
class Outer:
    seed: int = 0
    inner: Inner = field(default_factory=Inner)


def test_nested_config_flattens_to_dotted_params():
    assert config_params(Outer()) == {"seed": "0", "inner.gain": "2.0"}


def test_table_metrics_keep_finite_numbers_under_legal_names():
    table = [{"level": "3+ms", "err": 1.5, "bad": math.nan, "note": "x", "flag": True}]
    assert table_metrics(table, "level") == {"3_ms.err": 1.5}
    assert table_metrics(table, lambda row: f"L{row['level']}") == {"L3_ms.err": 1.5}
    assert metric_name("a+b/c d") == "a_b/c d"
