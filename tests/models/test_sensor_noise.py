"""A sensor's noise added to a model's uncertainty: Π = 1/(σ² + 1/Π_model), its derivative, and what it does to
perception with a GP fitted to noise-free data."""

from __future__ import annotations

import pytest
import torch

from bodyschema.aif.free_energy import sensory_terms
from bodyschema.aif.perception import Perception, PerceptionConfig
from bodyschema.models.sensor_noise import NoisySensor, with_sensor_noise
from tests.aif.toys import perturb, planar_poses
from tests.models.test_gpr import fit_gpr


@pytest.fixture(scope="module")
def gpr():
    return fit_gpr(60)


def test_precision_adds_the_sensor_variance_and_is_bounded_by_it(gpr):
    z = planar_poses(8, seed=0)
    own = gpr.precision(z)
    noisy = NoisySensor(gpr, 1e-3)
    assert torch.allclose(noisy.precision(z), 1 / (1e-6 + 1 / own), rtol=1e-12)
    assert (noisy.precision(z) < 1e6).all() and (own > 1e6).any(), "the GP alone claims more than the sensor gives"
    assert torch.equal(NoisySensor(gpr, 0.0).precision(z), own)
    assert torch.equal(noisy.predict(z), gpr.predict(z)) and noisy.modality == gpr.modality


def test_free_energy_gradient_matches_finite_differences_through_the_noise(gpr):
    """∂F/∂μ of F = ½εᵀΠ(μ)ε − ½ln|Π(μ)| with the noisy Π, its Π(μ) term included (precision_vjp's chain rule)."""
    noisy = NoisySensor(gpr, 3e-4)                     # comparable to the GP's own σ: both parts of Π vary
    q = planar_poses(6, seed=30)
    x = gpr.predict(q) + 1e-3 * torch.randn(6, 3, generator=torch.Generator().manual_seed(31), dtype=q.dtype)
    mu = perturb(q, seed=32, max_rad=0.1)

    def free(m):
        return sensory_terms([noisy], {"ee_xyz": x}, {"ee_xyz": None}, m, need_hessian=False)

    step = 1e-5
    fd = torch.stack([(free(mu + step * e).free_energy - free(mu - step * e).free_energy) / (2 * step)
                      for e in torch.eye(2, dtype=mu.dtype)], 1)           # (6, 2)
    assert (free(mu).grad - fd).norm() / fd.norm() < 1e-3


def test_sensor_noise_frees_perception_from_the_gps_log_determinant_pull(gpr):
    """With the GP's own Π(μ) the −½ln|Π(μ)| term holds beliefs away from the pose the ee reading gives; with a 1 mm
    sensor the belief lands on it."""
    q = planar_poses(30, seed=40)
    x = {"ee_xyz": gpr.predict(q)}
    mu0 = perturb(q, seed=41, max_rad=0.2)
    own = Perception([gpr]).infer(x, mu0)
    noisy = Perception([gpr], PerceptionConfig(sensor_noise=(("ee_xyz", 1e-3),))).infer(x, mu0)
    miss = lambda r: (gpr.predict(r.mu) - x["ee_xyz"]).norm(dim=-1)   # noqa: E731, (30,) m
    assert miss(noisy).max() < 1e-4 and (miss(own) > 1e-3).sum() >= 2, (miss(own), miss(noisy))
    assert (noisy.mu - q).abs().max() < 1e-3


def test_wrapping_twice_adds_the_variance_once_and_bad_input_raises(gpr):
    z = planar_poses(3, seed=1)
    once = with_sensor_noise([gpr], {"ee_xyz": 1e-3})
    twice = with_sensor_noise(once, {"ee_xyz": 1e-3})
    assert torch.equal(once[0].precision(z), twice[0].precision(z))
    assert with_sensor_noise(once, {})[0] is once[0]
    with pytest.raises(ValueError, match="sensor noise modality"):
        with_sensor_noise([gpr], {"image": 0.1})
    with pytest.raises(ValueError, match="sensor noise"):
        NoisySensor(gpr, -1.0)
    with pytest.raises(ValueError, match="sensor_noise"):
        PerceptionConfig(sensor_noise=(("ee_xyz", float("nan")),))
