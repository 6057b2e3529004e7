"""meta/stats.json of a LeRobot export holds LeRobot's full stats (min, max, mean, std, count, q01, q10, q50, q90, q99;
a policy normalised by QUANTILES needs q01 and q99) in LeRobot's shapes, and each equals numpy's statistic of the
exported data: the parquet's columns for vector features, every pixel / 255 per channel for images."""

from __future__ import annotations

import json

import numpy as np
import pytest
import zarr

from bodyschema.datagen.exchange.export import export_dataset
from bodyschema.datagen.exchange.export_lerobot_stats import _histogram_stats
from tests.datagen.export_stores import babble_store

pq = pytest.importorskip("pyarrow.parquet")

QUANTILES = {"q01": 0.01, "q10": 0.10, "q50": 0.50, "q90": 0.90, "q99": 0.99}   # LeRobot's DEFAULT_QUANTILES


def numpy_stats(values: np.ndarray, axis) -> dict[str, np.ndarray]:
    return {"min": values.min(axis), "max": values.max(axis), "mean": values.mean(axis), "std": values.std(axis),
            **{k: np.quantile(values, q, axis=axis) for k, q in QUANTILES.items()}}


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stats")
    store = babble_store(folder)
    out = export_dataset(store, folder / "lerobot", "lerobot")
    return zarr.open_group(str(store), mode="r"), out


def test_every_feature_has_lerobots_stats_equal_to_numpys(export):
    root, out = export
    info = json.loads((out / "meta" / "info.json").read_text())
    stats = json.loads((out / "meta" / "stats.json").read_text())
    tables = [pq.read_table(p) for p in sorted((out / "data").rglob("*.parquet"))]
    n = sum(t.num_rows for t in tables)
    assert set(stats) == set(info["features"])
    for key, feat in info["features"].items():
        got = stats[key]
        assert set(got) == {"count", *numpy_stats(np.zeros((2, 1)), 0)}, key
        assert got["count"] == [n], key
        if feat["dtype"] == "image":
            images = root["image"][:].astype(np.float64) / 255.0                  # (N, H, W, C)
            want = numpy_stats(images.reshape(-1, images.shape[-1]), 0)          # per channel, every pixel
            for k, v in want.items():
                assert np.shape(got[k]) == (images.shape[-1], 1, 1), (key, k)   # LeRobot's (C, 1, 1)
                np.testing.assert_allclose(np.ravel(got[k]), v, rtol=1e-12, atol=1e-12, err_msg=f"{key} {k}")
            continue
        column = np.concatenate([t.column(key).to_numpy(zero_copy_only=False) for t in tables])
        values = np.stack(column).astype(np.float64).reshape(n, -1)                 # (N, k) as exported
        for k, v in numpy_stats(values, 0).items():
            assert np.shape(got[k]) == tuple(feat["shape"]), (key, k)
            np.testing.assert_allclose(got[k], v, rtol=1e-12, atol=1e-12, err_msg=f"{key} {k}")
    assert np.all(np.array(stats["action"]["q01"]) < np.array(stats["action"]["q99"]))   # QUANTILES' denominator


@pytest.mark.parametrize("seed", range(5))
def test_the_histogram_statistics_are_numpys_of_the_values(seed):
    """uint8 pixels counted in 256 bins give numpy's exact statistics, quantile interpolation included (few values,
    gaps and a constant channel are where an order-statistic slip would show)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    values = rng.choice(rng.integers(0, 256, size=int(rng.integers(1, 6))), size=n)
    got = _histogram_stats(np.bincount(values, minlength=256))
    want = numpy_stats(values.astype(np.float64), None)
    np.testing.assert_allclose(got, [want[k] for k in ("min", "max", "mean", "std", *QUANTILES)], rtol=1e-12,
                               atol=1e-12)
