"""The MDN under the shared contract, plus its training: loss goes down, resume after a kill, bad data."""

import numpy as np
import pytest
import torch

from bodyschema.models.mdn import MDNModel
from tests.models.contract import SensoryModelContract
from tests.models.test_pixel import one_thread
from tests.toy_models import ToyPlanarArm

TINY = dict(hidden=(16, 16), n_components=2, epochs=25, batch_size=64, lr=1e-2, patience=100)


def toy_data(n: int, seed: int):
    """Joint angles in rad inside the toy arm's range and its exact ee_xyz. # (n, 2), (n, 3)"""
    gen = torch.Generator().manual_seed(seed)
    q = torch.rand(n, 2, generator=gen, dtype=torch.float64) * 4 - 2
    return q.float(), ToyPlanarArm().predict(q).float()


def tiny_mdn(**overrides) -> MDNModel:
    return MDNModel(ToyPlanarArm().body, "ee_xyz", (3,), **{**TINY, **overrides})


class TestMDN(SensoryModelContract):
    def make_model(self, seed):
        q, x = toy_data(256, seed=0)
        with one_thread():
            return tiny_mdn().fit(q, x, seed=seed, progress=False)

    def make_inputs(self, n, dtype=torch.float64):
        return toy_data(n, seed=100 + n)[0].to(dtype)

    def make_unfitted_model(self):
        return tiny_mdn()


@pytest.fixture
def tiny_threads():
    with one_thread():
        yield


@pytest.mark.usefixtures("tiny_threads")
def test_training_reduces_loss_and_fits_the_arm():
    q, x = toy_data(512, seed=0)
    q_val, x_val = toy_data(128, seed=1)
    losses = []
    model = tiny_mdn(epochs=60).fit(q, x, val=(q_val, x_val), progress=False,
                                    on_epoch=lambda e, m: losses.append(m))
    assert losses[-1]["train_loss"] < losses[0]["train_loss"] - 1.0, "NLL should drop by > 1 nat"
    assert {"train_loss", "val_loss"} <= set(losses[0])
    err = (model.predict(q_val.double()) - x_val.double())[:, :2]
    baseline = x_val.double()[:, :2] - x_val.double()[:, :2].mean(0)
    assert err.pow(2).mean() < 0.1 * baseline.pow(2).mean(), "R² on held-out poses should exceed 0.9"


@pytest.mark.usefixtures("tiny_threads")
def test_max_mode_predicts_a_component_mean_and_precision_is_positive():
    q, x = toy_data(256, seed=0)
    model = tiny_mdn(mode="max", epochs=5).fit(q, x, progress=False)
    z = toy_data(4, seed=3)[0].double()
    assert model.predict(z).shape == (4, 3) and (model.precision(z) > 0).all()
    logits, means, _ = model._net(z.dtype)(model.body.to_unit(z))
    chosen = means[torch.arange(4), logits.argmax(-1)] * model.x_scale_.double() + model.x_mean_.double()
    torch.testing.assert_close(model.predict(z), chosen)
    step = torch.zeros_like(z)
    step[:, 0] = 1e-6
    fd = (model.predict(z + step) - model.predict(z - step)) / 2e-6     # (4, 3): column 0 of the Jacobian
    torch.testing.assert_close(model.jacobian(z)[..., 0], fd, rtol=1e-4, atol=1e-6)


@pytest.mark.usefixtures("tiny_threads")
def test_killed_run_resumes_to_the_same_weights(tmp_path):
    q, x = toy_data(128, seed=0)
    full = tiny_mdn(epochs=3).fit(q, x, seed=7, progress=False)

    def kill(epoch, metrics):
        if epoch == 1:
            raise KeyboardInterrupt

    ckpt = tmp_path / "ckpt.pt"
    with pytest.raises(KeyboardInterrupt):
        tiny_mdn(epochs=3).fit(q, x, seed=7, progress=False, checkpoint=ckpt, on_epoch=kill)
    epochs_seen = []
    resumed = tiny_mdn(epochs=3).fit(q, x, seed=7, progress=False, checkpoint=ckpt,
                                     on_epoch=lambda e, m: epochs_seen.append(e))
    assert epochs_seen == [2], "resume must continue after the last completed epoch"
    for (name, a), b in zip(full.net_.state_dict().items(), resumed.net_.state_dict().values()):
        torch.testing.assert_close(a, b, rtol=0, atol=0, msg=f"weight {name} differs after resume")


@pytest.mark.usefixtures("tiny_threads")
def test_checkpoint_from_other_settings_is_refused(tmp_path):
    q, x = toy_data(64, seed=0)
    tiny_mdn(epochs=1).fit(q, x, progress=False, checkpoint=tmp_path / "c.pt")
    with pytest.raises(ValueError, match="checkpoint must be from a run with the same data"):
        tiny_mdn(epochs=2, lr=1e-3).fit(q, x, progress=False, checkpoint=tmp_path / "c.pt")


def test_fit_rejects_mismatched_lengths_nan_and_bad_shapes():
    q, x = toy_data(32, seed=0)
    with pytest.raises(ValueError, match=r"len\(x\) must be equal to len\(q\) = 32"):
        tiny_mdn().fit(q, x[:-1], progress=False)
    bad = x.numpy().copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="x must be finite"):
        tiny_mdn().fit(q.numpy(), bad, progress=False)
    with pytest.raises(ValueError, match=r"x must be of shape \(N, 3\)"):
        tiny_mdn().fit(q, x[:, :2], progress=False)
    with pytest.raises(TypeError, match="val must be a pair"):
        tiny_mdn().fit(q, x, val=q, progress=False)
    with pytest.raises(ValueError, match="mode must be one of"):
        tiny_mdn(mode="median")
    with pytest.raises(TypeError, match="q must be a numeric numpy array"):
        tiny_mdn().fit(np.array([["a", "b"]] * 32), x, progress=False)
    assert tiny_mdn(epochs=1).fit(q.tolist(), x.tolist(), progress=False).is_fitted   # array-likes (zarr) are fine
