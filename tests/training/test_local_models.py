"""`--model <dir>` specs: a model directory loads when the tracking database records its digest, is refused when
nothing vouches for it (unless the user says `trusted:`), and a state.pt holding a code pickle is the house error."""

import json
import os
import shutil

import pytest
import torch

from bodyschema.evaluation.core.specs import resolve_model
from bodyschema.models import load_model
from bodyschema.training.train import train
from tests.training.tiny_model import tiny_config


class _Payload:
    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_a_directory_logged_by_train_loads_and_a_changed_copy_is_refused(workdir, kin_store, tiny_kind):
    for register in (True, False):                          # registered, or only logged (its run records it)
        result = train(tiny_config(kin_store, epochs=3 + register, register=register))
        z = torch.zeros(2, 2, dtype=torch.float64)
        torch.testing.assert_close(resolve_model(str(result.model_dir)).predict(z),
                                   load_model(result.model_dir).predict(z), rtol=0, atol=0)

    copy = workdir / "edited"
    edited = load_model(result.model_dir)
    edited.weight_ = edited.weight_ * 1.01
    edited.save(copy)                                                # a well-formed model nobody logged
    with pytest.raises(ValueError, match=r"model directory .* must be a model logged by `bodyschema train` in "
                                         r"sqlite:///.*recorded nowhere.*pass trusted:"):
        resolve_model(str(copy))
    assert resolve_model(f"trusted:{copy}").predict(z).shape == (2, 3), "the explicit opt-in loads it"


def test_an_unverifiable_directory_is_refused_without_creating_a_tracking_store(tmp_path, monkeypatch, kin_store,
                                                                                  tiny_kind, workdir):
    result = train(tiny_config(kin_store, epochs=3))
    model_dir = result.model_dir.resolve()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)                               # the default store here does not exist
    monkeypatch.delenv("MLFLOW_TRACKING_URI")                  # (mlflow.set_tracking_uri exports it)
    with pytest.raises(ValueError, match="recorded nowhere"):
        resolve_model(str(model_dir))
    assert not (elsewhere / "mlflow.db").exists()
    resolve_model(str(model_dir), tracking_uri=f"sqlite:///{workdir / 'mlflow.db'}")   # the right store


def test_a_pickle_payload_as_state_pt_is_the_house_error_and_runs_nothing(workdir, kin_store, tiny_kind, tmp_path):
    result = train(tiny_config(kin_store, epochs=3, register=False))
    copy = shutil.copytree(result.model_dir, tmp_path / "payload")
    marker = tmp_path / "payload-ran"
    torch.save({"weight": _Payload(marker)}, copy / "state.pt")        # what a tampered checkpoint looks like
    meta = json.loads((copy / "meta.json").read_text())
    del meta["state_sha256"]       # whoever writes state.pt edits meta.json too: integrity, not authenticity
    (copy / "meta.json").write_text(json.dumps(meta))
    for spec in (f"trusted:{copy}",):
        with pytest.raises(ValueError, match=r"state.pt must be tensors only .* Refusing to run it") as info:
            resolve_model(spec)
        assert "weights_only" not in str(info.value) and info.value.__cause__ is None
    with pytest.raises(ValueError, match="recorded nowhere"):
        resolve_model(str(copy))                               # without the opt-in it is not even opened
    (copy / "state.pt").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(ValueError, match="state.pt must be a complete torch file"):
        resolve_model(f"trusted:{copy}")
    assert not marker.exists()


def test_a_spec_that_is_nothing_names_every_form(tmp_path):
    with pytest.raises(ValueError, match="model spec must be .*'trusted:<model directory>'"):
        resolve_model(f"trusted:{tmp_path / 'nowhere'}")
