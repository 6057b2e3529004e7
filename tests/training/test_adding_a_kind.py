"""The README's "Adding a model kind" recipe, followed to the letter so it cannot rot: one new file holding a toy
kind (its class, its capabilities, its config) and one registry line make it trainable from the CLI, trained and
registered by `train`, loaded by `load_model` and exported to ONNX, with no other file of the package touched."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest
import torch

from bodyschema.models import kinds, load_model
from bodyschema.training.config import TrainConfig
from bodyschema.training.train import train
from tests.test_cli_train import _help

# The one new file: `models/<kind>.py` in the package; here a module on a temporary path.
TOY_FILE = textwrap.dedent('''
    """A one-hidden-layer MLP of the scaled joints, fitted by the squared error (kind "toy-mlp")."""

    import math
    from dataclasses import dataclass
    from typing import ClassVar

    import torch
    from torch import nn

    from bodyschema.models._nn_fit import TrainSettings, build, check_fit_data, check_val, train
    from bodyschema.models._nn_model import NetModel
    from bodyschema.models.configs import ModelConfig
    from bodyschema.models.contract import BaseSensoryModel, register_kind


    @dataclass(frozen=True)
    class ToyMLPConfig(ModelConfig):
        kind: ClassVar[str] = "toy-mlp"
        width: int = 32  # hidden units
        epochs: int = 10  # at most this many passes over the training set
        batch_size: int = 64  # samples per gradient step
        lr: float = 3e-2  # Adam learning rate


    @register_kind
    class ToyMLP(NetModel, BaseSensoryModel):
        kind = "toy-mlp"
        exports_onnx = True          # its capability, declared here: `bodyschema export onnx` takes it

        def __init__(self, body, modality, output_shape, *, width=32, epochs=10, batch_size=64, lr=3e-2):
            super().__init__(body, modality, output_shape)
            self.width = width
            self.settings = TrainSettings(epochs, batch_size, lr, patience=epochs)
            self.precision_ = None

        def fit(self, q, x, *, seed=0, val=None, on_epoch=None, progress=True, checkpoint=None):
            q, x = check_fit_data(q, x, self.latent_dim, self.output_shape)
            val = check_val(val, self.latent_dim, self.output_shape)
            gen = torch.Generator().manual_seed(seed)
            net = build(self._factory, gen)
            pair = lambda q_, x_: (self.body.to_unit(q_), x_.reshape(len(x_), -1))
            train(net, lambda n, u, y: ((n(u) - y) ** 2).mean(), pair(q, x), self.settings, gen,
                  val=pair(*val) if val is not None else None, on_epoch=on_epoch, progress=progress,
                  checkpoint=checkpoint)
            self._set_net(net)
            residual = self.predict(q.double()) - x.double()
            self.precision_ = 1.0 / residual.pow(2).mean(0).clamp_min(1e-12)
            return self

        def _factory(self):
            out = math.prod(self.output_shape)
            return nn.Sequential(nn.Linear(self.latent_dim, self.width), nn.Tanh(), nn.Linear(self.width, out))

        def _outputs(self, net, u):
            return net(u).reshape(-1, *self.output_shape)

        def _precision(self, z):
            return self.precision_.to(z.dtype).expand(z.shape[0], *self.output_shape)

        def _config(self):
            s = self.settings
            return {"width": self.width, "epochs": s.epochs, "batch_size": s.batch_size, "lr": s.lr}

        def _state(self):
            return {**super()._state(), "precision": self.precision_}

        @classmethod
        def _from_saved(cls, body, modality, output_shape, config, state):
            model = cls(body, modality, output_shape, **config)
            model.precision_ = state["precision"]
            model._restore_net(model._factory, state)
            return model
''')
# The one registry line (in models/kinds.py's table for a shipped kind):
REGISTRY_LINE = ('kinds.register(kinds.Kind("toy-mlp", "toy_mlp", "ToyMLP", "ToyMLP", "ToyMLPConfig", '
                 'summary="A toy MLP: the README recipe."))')


@pytest.fixture
def toy_kind(tmp_path, monkeypatch):
    """The toy kind's file on the import path and its registry line run; both undone after the test."""
    folder = tmp_path / "plugin"
    folder.mkdir()
    (folder / "toy_mlp.py").write_text(TOY_FILE)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setitem(kinds.KINDS, "toy-mlp", None)          # registered below; removed again at teardown
    monkeypatch.setitem(kinds._classes, "toy-mlp", None)
    exec(REGISTRY_LINE, {"kinds": kinds})
    yield kinds.get("toy-mlp")
    sys.modules.pop("toy_mlp", None)


def test_the_registry_line_lists_the_kind_and_its_flags_on_the_cli(toy_kind, capsys, monkeypatch):
    assert "toy-mlp" in _help(["train"], capsys, monkeypatch)
    flags = _help(["train", "toy-mlp"], capsys, monkeypatch)
    assert "--width INT hidden units (default: 32)" in flags, "the config in the kind's file gives the flags"


def test_the_toy_kind_trains_registers_loads_and_exports(toy_kind, kin_store, workdir, tmp_path):
    from bodyschema.models.onnx_export import export_onnx, read_metadata
    from bodyschema.training import guards, registry
    from bodyschema.training.data import load_dataset

    config = TrainConfig(model=toy_kind.config_class(), data=kin_store, progress=False)
    assert config.modality == "ee_xyz", "the kind's default modality"
    result = train(config)
    assert result.registered_name == "bodyschema-planar2-ee_xyz-toy-mlp" and result.champion

    model = load_model(result.model_dir)
    assert type(model).__name__ == "ToyMLP" and model.kind == "toy-mlp"
    champion = registry.load(f"models:/{result.registered_name}@champion")     # digest-checked, from the registry
    assert type(champion) is type(model)
    data = load_dataset(kin_store, "ee_xyz")
    q, x = torch.as_tensor(data.val.q, dtype=torch.float64), np.asarray(data.val.x, dtype=np.float64)
    rmse = float(np.sqrt(((model.predict(q).numpy() - x) ** 2).mean()))
    assert rmse == pytest.approx(result.metrics["val_rmse"], rel=1e-5), "the loaded model is the scored one"
    assert rmse < x.std(), "it learned more than the mean"
    torch.testing.assert_close(champion.predict(q), model.predict(q), rtol=0, atol=0)
    assert guards.net_sizes(model)[0] > 0, "the network memory guard sizes it from its _factory"

    path = export_onnx(model, tmp_path / "toy.onnx")
    meta = read_metadata(path)
    assert meta["bodyschema.kind"] == "toy-mlp" and meta["bodyschema.output"].endswith("ee_xyz in m")
