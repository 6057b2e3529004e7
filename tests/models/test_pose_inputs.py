"""What the conv decoder reads of the pose: each kind's derivatives against autograd, its sizes, its errors."""

import pytest
import torch

from bodyschema.models.pose_inputs import INPUTS, PRODUCTS, ProductInputs, pose_inputs
from bodyschema.models.scaling import BodySpec


def body(joints: int) -> BodySpec:
    low, high = tuple(-1.0 - 0.3 * i for i in range(joints)), tuple(2.0 + 0.1 * i for i in range(joints))
    return BodySpec("arm", tuple(f"j{i}" for i in range(joints)), low, high)


def started(kind: str, joints: int):
    module = pose_inputs(kind, body(joints)).double()
    if isinstance(module, ProductInputs):
        module.start(torch.Generator().manual_seed(0))
        module.double()
    return module


@pytest.mark.parametrize("kind", INPUTS)
def test_derivatives_equal_autograds_and_values_equal_the_forward(kind):
    module = started(kind, 3)
    u = torch.rand(4, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64) * 2 - 1
    values, slopes = module.with_derivatives(u)                        # (B, P), (B, D, P)
    torch.testing.assert_close(values, module(u), rtol=0, atol=1e-14)
    for i in range(len(u)):                                            # autograd's (P, D) per pose
        reference = torch.autograd.functional.jacobian(module, u[i:i + 1])[0, :, 0]
        torch.testing.assert_close(slopes[i].T, reference, rtol=1e-12, atol=1e-12)


def test_sizes_and_products_start_near_one_varying_with_every_joint():
    assert [pose_inputs(kind, body(5)).size for kind in INPUTS] == [5, 3 ** 5, 3 ** 5]   # products: ≤ PRODUCTS
    assert pose_inputs("products", body(6)).size == PRODUCTS
    module = started("products", 9)                                    # past the kinematic kind's 7 joints
    u = torch.rand(512, 9, generator=torch.Generator().manual_seed(2), dtype=torch.float64) * 2 - 1
    with torch.no_grad():
        values, slopes = module.with_derivatives(u)
    assert values.shape == (512, 256) and slopes.shape == (512, 9, 256)
    assert abs(float(values.mean())) < 0.2                              # less their constant part: centred
    assert bool((slopes.abs().mean((0, 2)) > 1e-2).all())              # every joint moves the products


def test_bad_kinds_raise_the_house_error():
    with pytest.raises(ValueError, match=r"inputs must be one of \('unit', 'products', 'kinematic'\). Got 'fourier'"):
        pose_inputs("fourier", body(3))
    with pytest.raises(ValueError, match=r"inputs 'kinematic' must be used on at most 7 joints .*Got 8. Use inputs "
                                         r"'products'"):
        pose_inputs("kinematic", body(8))
