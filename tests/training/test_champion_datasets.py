"""The champion rule compares only versions scored on the same validation data (issue 35 item 5): a better score on
another store, or on another held-out split of the same store, does not move `@champion`; `registry list` shows each
version's dataset and digest."""

from __future__ import annotations

import pytest

from bodyschema.training.champion import same_validation_data
from bodyschema.training.data import load_dataset, validation_digest
from bodyschema.training.registry import list_models, use_tracking
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config

NAME = "bodyschema-planar2-ee_xyz-tiny"


@pytest.fixture(scope="module")
def other_store(tmp_path_factory):
    """Another planar2 store (another seed: other poses), as an imported store beside a simulated one."""
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    out = tmp_path_factory.mktemp("stores") / "other.zarr"
    return generate(DatagenConfig(robot="planar2", n=400, images=False, out=out, shard_size=100, seed=1),
                    progress=False)


def champion() -> str:
    return str(use_tracking().get_model_version_by_alias(NAME, "champion").version)


def test_a_better_score_on_other_validation_data_does_not_move_the_champion(workdir, kin_store, other_store,
                                                                             tiny_kind, capsys):
    first = train(tiny_config(kin_store, epochs=10))
    assert first.champion
    elsewhere = train(tiny_config(other_store, epochs=40))                 # another store
    resplit = train(tiny_config(kin_store, epochs=40, seed=1))             # the same store, other held-out rows
    for result in (elsewhere, resplit):
        assert result.metrics["val_rmse"] < first.metrics["val_rmse"], "premise: it would have won on the score"
        assert not result.champion
        assert "champion unchanged" in str(result)
    assert champion() == first.model_version == "1"
    better = train(tiny_config(kin_store, epochs=40))                      # same data, better: moves as before
    assert better.champion and champion() == better.model_version == "4"

    client = use_tracking()
    tags = {v: client.get_model_version(NAME, v).tags for v in "1234"}
    assert tags["1"]["val_sha256"] == tags["4"]["val_sha256"] == validation_digest(load_dataset(kin_store, "ee_xyz"))
    assert len({t["val_sha256"] for t in tags.values()}) == 3

    rows = list_models()
    assert [(r.version, r.dataset) for r in rows] == [("1", "kin.zarr"), ("2", "other.zarr"), ("3", "kin.zarr"),
                                                      ("4", "kin.zarr")]
    assert [r.dataset_sha256 for r in rows] == [tags[v]["dataset_sha256"] for v in "1234"]
    line = str(rows[1])
    assert f"dataset=other.zarr sha256={tags['2']['dataset_sha256'][:16]}" in line


def test_versions_registered_before_the_validation_digest_compare_by_their_dataset():
    old, new = {"dataset_sha256": "a"}, {"dataset_sha256": "a", "val_sha256": "x"}
    assert same_validation_data(old, new) and same_validation_data(new, old)
    assert not same_validation_data(old, {"dataset_sha256": "b", "val_sha256": "x"})
    assert not same_validation_data({}, {})
    assert not same_validation_data({**new, "val_sha256": "y"}, new)
