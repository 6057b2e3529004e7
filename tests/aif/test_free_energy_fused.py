"""An image model's terms from one forward (g with J, or g with Jᵀv) equal the separate calls' (the chunked path)."""

from __future__ import annotations

import pytest
import torch

from bodyschema.aif.free_energy import sensory_terms
from tests.models.test_pixel import blob_images, joint_angles, tiny_decoder
from tests.threads import one_thread


class Separate:
    """The decoder without its fused calls: sensory_terms falls back to predict, vjp and the chunked Jacobian."""

    def __init__(self, model):
        self._model = model

    def __getattr__(self, name):
        if name in ("predict_and_jacobian", "predict_and_vjp"):
            raise AttributeError(name)
        return getattr(self._model, name)


@pytest.mark.parametrize("need_hessian", [True, False])
def test_fused_terms_equal_the_separate_calls(need_hessian):
    q = joint_angles(64, seed=0)
    with one_thread():
        model = tiny_decoder().fit(q, blob_images(q), seed=0, progress=False)
    mu = joint_angles(5, seed=1).double()
    obs = {"image": blob_images(joint_angles(5, seed=2)).double()}
    fused = sensory_terms([model], obs, {}, mu, need_hessian)
    separate = sensory_terms([Separate(model)], obs, {}, mu, need_hessian)
    # float32 networks: the fused pass batches the pose with its tangents, which may reorder sums in the last bits
    torch.testing.assert_close(fused.free_energy, separate.free_energy, rtol=1e-6, atol=0)
    torch.testing.assert_close(fused.grad, separate.grad, rtol=1e-5, atol=1e-9)
    if need_hessian:
        torch.testing.assert_close(fused.hessian, separate.hessian, rtol=1e-5, atol=1e-9)
