"""The pixel decoder's written-out forward-mode Jacobian against autograd's (`vmap(jacfwd)`, the generic NetModel
path) and against central finite differences, for both capacities, each input (pose_inputs.py), grayscale and
colour, in float32 and float64."""

import pytest
import torch

from bodyschema.models._nn_model import NetModel
from tests.models.test_pixel import HW, joint_angles, tiny_decoder
from tests.threads import one_thread

# float32: the two forward modes sum the same products in a different order, so they agree to a few float32 ulps of
# the largest entry; float64: to rounding.
TOL = {torch.float32: 1e-5, torch.float64: 1e-12}
FD_STEP, FD_TOL = 1e-6, 1e-7    # float64 central differences: O(h²) truncation + O(eps/h) rounding, relative


def trained(size: str, shape=HW, inputs: str = "products"):
    """A briefly trained decoder (non-trivial weights) of the `size` preset at `shape`."""
    q = joint_angles(64, seed=0)
    gen = torch.Generator().manual_seed(1)
    images = torch.rand(64, *shape, generator=gen)
    overrides = {"fc_hidden": None, "channels": None} if size == "pixel_aif" else {}
    with one_thread():
        return tiny_decoder(shape, size=size, epochs=2, inputs=inputs, **overrides).fit(q, images, seed=0,
                                                                                       progress=False)


def relative(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a - b).abs().max() / b.abs().max())


@pytest.mark.parametrize("size,shape,inputs", [("lean", HW, "products"), ("lean", HW, "unit"),
                                               ("lean", HW, "kinematic"), ("lean", (*HW, 3), "products"),
                                               ("pixel_aif", HW, "products")])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_jacobian_equals_autograd_jacfwd(size, shape, inputs, dtype):
    model = trained(size, shape, inputs)
    z = joint_angles(5, seed=7).to(dtype)
    with one_thread():
        jac = model.jacobian(z)                                      # (B, O, Dz)
        reference = NetModel._jacobian(model, z)
    assert jac.shape == reference.shape and jac.dtype == dtype
    assert relative(jac, reference) < TOL[dtype]


@pytest.mark.parametrize("inputs", ["products", "unit", "kinematic"])
def test_jacobian_equals_central_finite_differences(inputs):
    model = trained("lean", inputs=inputs)
    z = joint_angles(3, seed=8).double()
    jac = model.jacobian(z)                                          # (B, O, Dz)
    columns = []
    for j in range(z.shape[1]):
        step = torch.zeros_like(z)
        step[:, j] = FD_STEP
        columns.append((model.predict(z + step) - model.predict(z - step)).reshape(len(z), -1) / (2 * FD_STEP))
    assert relative(jac, torch.stack(columns, -1)) < FD_TOL


def test_predict_and_jacobian_match_the_separate_calls():
    model = trained("lean")
    z = joint_angles(4, seed=9)
    x_hat, jac = model.predict_and_jacobian(z)
    torch.testing.assert_close(x_hat, model.predict(z), rtol=0, atol=1e-6)
    torch.testing.assert_close(jac, model.jacobian(z), rtol=0, atol=0)
    with pytest.raises(ValueError, match="z must be"):
        model.predict_and_jacobian(z[:, :1])


def test_one_row_equals_its_row_in_a_batch():
    model = trained("lean")
    z = joint_angles(4, seed=10).double()
    torch.testing.assert_close(model.jacobian(z[2:3])[0], model.jacobian(z)[2], rtol=1e-12, atol=1e-12)
