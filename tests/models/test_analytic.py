"""AnalyticModel (MuJoCo FK oracle) on nao_arm: the shared SensoryModel contract plus oracle-specific checks."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from bodyschema.datagen.body.kinematics import VECTORIZE_FROM
from bodyschema.datagen.body.robot import Robot
from bodyschema.models import load_model
from bodyschema.models.analytic import DEFAULT_PRECISION, AnalyticModel
from tests.models.contract import SensoryModelContract

ROBOT = "nao_arm"


class _AnalyticNao(SensoryModelContract):
    modality = ""

    def make_model(self, seed: int):
        return AnalyticModel(ROBOT, self.modality)          # nothing random: seed unused

    def make_inputs(self, n: int, dtype=torch.float64) -> torch.Tensor:
        ranges = torch.tensor(Robot.load(ROBOT).sampling_ranges, dtype=dtype)     # (Dz, 2) rad
        gen = torch.Generator().manual_seed(1000 + n)
        u = torch.rand(n, ranges.shape[0], generator=gen, dtype=dtype)
        return ranges[:, 0] + u * (ranges[:, 1] - ranges[:, 0])

    def make_unfitted_model(self):
        raise NotImplementedError                            # nothing to fit


class TestAnalyticEeXyz(_AnalyticNao):
    modality = "ee_xyz"


class TestAnalyticEeRot(_AnalyticNao):
    modality = "ee_rot"


class TestAnalyticEePixel(_AnalyticNao):
    modality = "ee_pixel"


class TestAnalyticJoints(_AnalyticNao):
    modality = "joints"


# ---- oracle-specific --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def nao():
    return Robot.load(ROBOT)


@pytest.mark.parametrize("batch", [6, VECTORIZE_FROM + 1])                     # per-pose MuJoCo / numpy chain
def test_predictions_equal_the_robot_kinematics_and_camera(nao, batch):
    q = np.random.default_rng(0).uniform(*nao.sampling_ranges.T, size=(batch, nao.dq))
    z = torch.from_numpy(q)
    np.testing.assert_allclose(AnalyticModel(ROBOT, "ee_xyz").predict(z).numpy(), nao.fk(q), atol=1e-12)
    np.testing.assert_allclose(AnalyticModel(ROBOT, "ee_pixel").predict(z).numpy(), nao.project(nao.fk(q)),
                               atol=1e-9)
    np.testing.assert_allclose(AnalyticModel(ROBOT, "ee_xyz").jacobian(z).numpy(), nao.jacobian(q), atol=1e-12)
    pixel_jac = np.einsum("nij,njk->nik", nao.project_jacobian(nao.fk(q)), nao.jacobian(q))
    np.testing.assert_allclose(AnalyticModel(ROBOT, "ee_pixel").jacobian(z).numpy(), pixel_jac, atol=1e-9)
    torch.testing.assert_close(AnalyticModel(ROBOT, "joints").predict(z), z)
    rot, rot_jac = nao.ee_rot_and_jacobian(q)
    np.testing.assert_allclose(AnalyticModel(ROBOT, "ee_rot").predict(z).numpy(), rot, atol=1e-12)
    np.testing.assert_allclose(AnalyticModel(ROBOT, "ee_rot").jacobian(z).numpy(), rot_jac, atol=1e-12)


def test_bigger_image_scales_pixels_about_the_principal_point(nao):
    q = torch.from_numpy(np.random.default_rng(1).uniform(*nao.sampling_ranges.T, size=(4, nao.dq)))
    small, big = AnalyticModel(ROBOT, "ee_pixel"), AnalyticModel(ROBOT, "ee_pixel", image_size=(112, 160))
    centre_small = torch.tensor([79 / 2, 55 / 2], dtype=torch.float64)
    centre_big = torch.tensor([159 / 2, 111 / 2], dtype=torch.float64)
    torch.testing.assert_close(big.predict(q) - centre_big, 2 * (small.predict(q) - centre_small))


def test_default_precisions_are_one_mm_one_px_one_degree():   # ee_rot: 1° as a rotation-matrix entry
    z = torch.zeros(2, 4, dtype=torch.float64)
    assert AnalyticModel(ROBOT, "ee_xyz").precision(z)[0, 0].item() == pytest.approx(1e6)
    assert AnalyticModel(ROBOT, "ee_pixel").precision(z)[0, 0].item() == pytest.approx(1.0)
    assert AnalyticModel(ROBOT, "joints").precision(z)[0, 0].item() == pytest.approx((180 / np.pi) ** 2)
    assert AnalyticModel(ROBOT, "ee_xyz", precision=4.0).precision(z).unique().item() == 4.0
    assert AnalyticModel(ROBOT, "ee_rot").precision(z)[0, 0].item() == pytest.approx((180 / np.pi) ** 2)
    assert set(DEFAULT_PRECISION) == {"ee_xyz", "ee_rot", "ee_pixel", "joints"}


def test_body_uses_the_robot_joints_and_sampling_ranges(nao):
    body = AnalyticModel(ROBOT, "ee_xyz").body
    assert body.robot == ROBOT and body.joint_names == nao.joint_names
    np.testing.assert_allclose(np.c_[body.q_low, body.q_high], nao.sampling_ranges)


def test_saves_only_the_config(tmp_path):
    AnalyticModel(ROBOT, "ee_pixel", image_size=(28, 40), precision=2.0).save(tmp_path / "m")
    meta = json.loads((tmp_path / "m" / "meta.json").read_text())
    assert meta["kind"] == "analytic" and meta["config"]["image_size"] == [28, 40]
    assert torch.load(tmp_path / "m" / "state.pt", weights_only=True) == {}
    loaded = load_model(tmp_path / "m")
    assert isinstance(loaded, AnalyticModel) and loaded.image_size == (28, 40) and loaded.fixed_precision == 2.0


def test_changed_mjcf_is_reported_on_load(tmp_path):
    AnalyticModel(ROBOT, "ee_xyz").save(tmp_path / "m")
    meta_file = tmp_path / "m" / "meta.json"
    meta = json.loads(meta_file.read_text())
    meta["config"]["mjcf_sha256"] = "0" * 64
    meta_file.write_text(json.dumps(meta))
    with pytest.warns(UserWarning, match="shipped MJCF of 'nao_arm' changed"):
        load_model(tmp_path / "m")


def test_fk_is_defined_outside_the_joint_limits():
    z = torch.tensor([[3.0, 2.0, 3.0, 0.5]], dtype=torch.float64)            # beyond every NAO limit
    assert torch.isfinite(AnalyticModel(ROBOT, "ee_xyz").predict(z)).all()


def test_bad_config_raises():
    with pytest.raises(ValueError, match=r"modality must be one of \('ee_xyz', 'ee_rot', 'ee_pixel', 'joints'\)"):
        AnalyticModel(ROBOT, "image")
    with pytest.raises(ValueError, match=r"robot must be one of"):
        AnalyticModel("atlas", "ee_xyz")
    with pytest.raises(ValueError, match=r"precision must be a finite number > 0"):
        AnalyticModel(ROBOT, "ee_xyz", precision=-1.0)


@pytest.mark.parametrize("robot, modality", [("planar2", "ee_xyz"), ("nao_arm", "ee_pixel")])
def test_a_pickled_analytic_model_predicts_as_the_original(robot, modality):
    """A worker process gets the model pickled: the robot's cached views into its MjData must follow it (they were
    copies after pickling, and fk returned the zero pose)."""
    import pickle

    model = AnalyticModel(robot, modality)
    copy = pickle.loads(pickle.dumps(model))
    low, high = model.robot.sampling_ranges.T
    z = torch.as_tensor(np.random.default_rng(0).uniform(low, high, (5, len(low))))
    assert torch.equal(copy.predict(z), model.predict(z))
    assert torch.equal(copy.jacobian(z), model.jacobian(z))
