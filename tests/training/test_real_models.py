"""Every real model kind through `train` on small stores (few epochs): logged, registered, loaded back unchanged."""

import pytest
import torch

from bodyschema.models import load_model
from bodyschema.models.configs import GPRConfig, MDNConfig, MultimodalConfig, PixelConfig, SklearnGPRConfig
from bodyschema.training.config import TrainConfig
from bodyschema.training.registry import load
from bodyschema.training.train import train

CASES = {   # kind: (store fixture, modality, hyper-parameters that keep the fit to about a second)
    "mdn": ("kin_store", "ee_xyz", MDNConfig(epochs=3, hidden=(16,))),
    "gpr": ("kin_store", "ee_pixel", GPRConfig(hyper_points=40, max_points=150, adam_steps=3, lbfgs_steps=5)),
    "sklearn-gpr": ("kin_store", "ee_xyz", SklearnGPRConfig(hyper_points=40, max_points=150, max_iter=5)),
    "pixel": ("image_store", "image", PixelConfig(epochs=2, channels=(8, 4), fc_hidden=16)),
    "multimodal": ("image_store", "ee_xyz,image", MultimodalConfig(epochs=2, channels=(8, 4), fc_hidden=16,
                                                                   hidden=(16,))),
}


SLOW = {"sklearn-gpr"}   # same path through `train` as gpr (no checkpoint, vector output)


@pytest.mark.parametrize("kind", [pytest.param(k, marks=pytest.mark.slow) if k in SLOW else k for k in CASES])
def test_kind_trains_registers_and_loads_back(kind, workdir, request):
    store_fixture, modality, hyper = CASES[kind]
    store = request.getfixturevalue(store_fixture)
    result = train(TrainConfig(model=hyper, data=store, modality=modality, progress=False))
    modalities = modality.split(",")
    assert [r.modality for r in result.registered] == modalities
    assert all(r.champion and r.version == "1" for r in result.registered)
    z = torch.tensor([[0.3, -0.4], [1.0, 0.5]], dtype=torch.float64)
    for reg in result.registered:
        assert reg.name == f"bodyschema-planar2-{reg.modality}-{kind}"
        model = load(f"models:/{reg.name}@champion", expect_modality=reg.modality)
        saved = load_model(result.model_dirs[reg.modality])
        torch.testing.assert_close(model.predict(z), saved.predict(z), rtol=0, atol=0)
        key = f"{reg.modality}/val_rmse" if len(modalities) > 1 else "val_rmse"
        assert 0 < result.metrics[key] < float("inf")
