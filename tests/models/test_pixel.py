"""The pixel decoder under the shared contract on tiny blob images, plus its training and its layout."""

import json

import pytest
import torch

from bodyschema.models.contract import load_model
from bodyschema.models.pixel import SIZES, PixelDecoder
from tests.models.contract import SensoryModelContract
from tests.threads import one_thread
from tests.toy_models import ToyPlanarArm

TINY = dict(fc_hidden=16, channels=(8, 4), epochs=15, batch_size=32, lr=1e-2, patience=100)
HW = (8, 12)


def blob_images(q: torch.Tensor, shape=HW, width_px: float = 1.5) -> torch.Tensor:
    """A camera over the toy arm: a Gaussian blob at its end effector. q (N, 2) rad → (N, *shape) in [0, 1]."""
    h, w = shape[:2]
    ee = ToyPlanarArm().predict(q.double())[:, :2]                      # (N, 2) m, inside ±0.55 m
    row = (0.5 - ee[:, 1] / 1.2) * (h - 1)                              # (N,) px
    col = (0.5 + ee[:, 0] / 1.2) * (w - 1)
    rr, cc = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    d2 = (rr - row[:, None, None]) ** 2 + (cc - col[:, None, None]) ** 2   # (N, H, W)
    img = torch.exp(-d2 / (2 * width_px ** 2))
    if len(shape) == 3:
        img = torch.stack([img * (c + 1) / shape[2] for c in range(shape[2])], -1)   # (N, H, W, C)
    return img.float()


def peak_px(images: torch.Tensor) -> torch.Tensor:
    """(row, col) of the brightest pixel. (N, H, W) → (N, 2)"""
    idx = images.reshape(len(images), -1).argmax(1)
    return torch.stack([idx // images.shape[2], idx % images.shape[2]], -1).double()


def joint_angles(n: int, seed: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return (torch.rand(n, 2, generator=gen, dtype=torch.float64) * 4 - 2).float()   # (n, 2) rad


def tiny_decoder(shape=HW, **overrides) -> PixelDecoder:
    return PixelDecoder(ToyPlanarArm().body, "image", shape, **{**TINY, **overrides})


class TestPixelDecoder(SensoryModelContract):
    batch = 4

    def make_model(self, seed):
        q = joint_angles(128, seed=0)
        with one_thread():
            return tiny_decoder().fit(q, blob_images(q), seed=seed, progress=False)

    def make_inputs(self, n, dtype=torch.float64):
        return joint_angles(n, seed=100 + n).to(dtype)

    def make_unfitted_model(self):
        return tiny_decoder()


class TestPixelAIFSizedDecoder(TestPixelDecoder):
    """The "pixel_aif" capacity (FC 512, 3×3 refinement convolutions) under the same contract, at 8×12 px."""

    def make_model(self, seed):
        q = joint_angles(128, seed=0)
        with one_thread():
            return tiny_decoder(size="pixel_aif", fc_hidden=None, channels=None, epochs=4).fit(
                q, blob_images(q), seed=seed, progress=False)

    def make_unfitted_model(self):
        return tiny_decoder(size="pixel_aif", fc_hidden=None, channels=None)


def test_pixel_aif_size_has_pixel_aifs_layout_at_56x80():
    net = PixelDecoder(ToyPlanarArm().body, "image", (56, 80), size="pixel_aif")._factory()
    assert [m.out_features for m in net.fc if isinstance(m, torch.nn.Linear)] == [512, 1120]
    ups = [(m.in_channels, m.out_channels) for m in net.up if isinstance(m, torch.nn.ConvTranspose2d)]
    assert ups == [(16, 64), (64, 16), (16, 1)]
    refines = [(m.in_channels, m.kernel_size) for m in net.up if isinstance(m, torch.nn.Conv2d)
               and not isinstance(m, torch.nn.ConvTranspose2d)]
    assert refines == [(64, (3, 3)), (16, (3, 3))]
    assert net(torch.zeros(2, 2)).shape == (2, 56, 80)


def test_size_is_saved_and_explicit_values_override_the_preset(tmp_path):
    model = TestPixelAIFSizedDecoder().make_model(seed=0)
    model.save(tmp_path / "m")
    loaded = PixelDecoder.load(tmp_path / "m")
    assert (loaded.size, loaded.fc_hidden, loaded.channels, loaded.refine) == ("pixel_aif", 512, (16, 64, 16), True)
    override = PixelDecoder(ToyPlanarArm().body, "image", HW, size="pixel_aif", fc_hidden=32, refine=False)
    assert (override.fc_hidden, override.channels, override.refine) == (32, (16, 64, 16), False)
    with pytest.raises(ValueError, match=r"size must be one of \['lean', 'pixel_aif', 'splat'\]. Got 'huge'"):
        PixelDecoder(ToyPlanarArm().body, "image", HW, size="huge")


def test_to_cpu_is_a_no_op_that_keeps_outputs_bit_for_bit():
    model = TestPixelDecoder().make_model(seed=0)
    z = joint_angles(3, seed=5)
    v = torch.randn(3, *HW, generator=torch.Generator().manual_seed(0))
    before = (model.predict(z), model.jacobian(z), model.vjp(z, v), model.precision(z))
    assert model.to("cpu") is model and model.device == torch.device("cpu")
    after = (model.predict(z), model.jacobian(z), model.vjp(z, v), model.precision(z))
    for a, b in zip(before, after):
        torch.testing.assert_close(a, b, rtol=0, atol=0)


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on a machine without CUDA")
def test_cuda_without_cuda_raises_the_house_error():
    model = TestPixelDecoder().make_model(seed=0)
    with pytest.raises(ValueError, match=r"device must be 'cpu' or an available CUDA device. Got 'cuda'. CUDA is "
                                         r"not available on this machine: use --device cpu"):
        model.to("cuda")
    with pytest.raises(ValueError, match=r"device must be .*Got 'gpu'"):
        model.to("gpu")
    q = joint_angles(16, seed=0)
    with pytest.raises(ValueError, match=r"device must be 'cpu' or an available CUDA device"):
        tiny_decoder().fit(q, blob_images(q), progress=False, device="cuda:1")


@pytest.fixture
def tiny_threads():
    with one_thread():
        yield


@pytest.mark.usefixtures("tiny_threads")
@pytest.mark.parametrize("loss", ["cross_entropy", "mse"])
def test_training_reduces_loss_and_puts_the_blob_in_place(loss):
    q, q_val = joint_angles(256, seed=0), joint_angles(64, seed=1)
    x_val = blob_images(q_val)
    losses = []
    model = tiny_decoder(epochs=40, loss=loss).fit(q, blob_images(q), val=(q_val, x_val), progress=False,
                                                   on_epoch=lambda e, m: losses.append(m["val_loss"]))
    x = x_val.double().clamp(1e-12, 1 - 1e-12)
    least = float(-(x * x.log() + (1 - x) * (1 - x).log()).mean()) if loss == "cross_entropy" else 0.0
    assert losses[-1] - least < 0.3 * (losses[0] - least)      # the cross-entropy's least is the targets' entropy
    pred = model.predict(q_val.double())                                 # (64, 8, 12)
    assert (peak_px(pred) - peak_px(x_val)).norm(dim=1).median() <= 1.5, "blob peak should be within ~1 px"
    mse = (pred - x_val.double()).pow(2).mean()
    assert model.precision_ == pytest.approx(1 / float(mse), rel=1e-3), "precision = 1 / validation residual MSE"


@pytest.mark.usefixtures("tiny_threads")
def test_colour_images_uint8_input_and_fixed_precision():
    q = joint_angles(64, seed=0)
    x = (blob_images(q, (7, 9, 3)) * 255).round().to(torch.uint8).numpy()
    model = tiny_decoder((7, 9, 3), epochs=2, precision=50.0).fit(q.numpy(), x, progress=False)
    z = joint_angles(3, seed=2).double()
    out = model.predict(z)
    assert out.shape == (3, 7, 9, 3) and ((out > 0) & (out < 1)).all()
    assert (model.precision(z) == 50.0).all()
    assert model.jacobian(z).shape == (3, 7 * 9 * 3, 2)


def test_loaded_decoder_keeps_the_fast_layout(tmp_path):
    model = TestPixelDecoder().make_model(seed=0)
    model.save(tmp_path / "m")
    loaded = PixelDecoder.load(tmp_path / "m")
    assert all(m.weight.is_contiguous(memory_format=torch.channels_last)
               for m in loaded.net_.modules() if isinstance(m, torch.nn.ConvTranspose2d))


def test_bad_images_and_shapes_raise():
    q = joint_angles(16, seed=0)
    with pytest.raises(ValueError, match=r"x must be of shape \(N, 8, 12\)"):
        tiny_decoder().fit(q, blob_images(q, (8, 10)), progress=False)
    with pytest.raises(ValueError, match="output_shape must be"):
        tiny_decoder((96,))
    with pytest.raises(ValueError, match="precision must be > 0"):
        tiny_decoder(precision=0.0)


def test_predict_and_vjp_reuses_one_forward_and_matches_the_separate_calls():
    model = TestPixelDecoder().make_model(seed=0)
    z = joint_angles(3, seed=4).double()
    v = torch.randn(3, *HW, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    x_hat, vjp = model.predict_and_vjp(z)
    torch.testing.assert_close(x_hat, model.predict(z), rtol=0, atol=0)
    torch.testing.assert_close(vjp(v), model.vjp(z, v))
    torch.testing.assert_close(vjp(2 * v), 2 * model.vjp(z, v))   # callable more than once
    with pytest.raises(ValueError, match="v must be"):
        vjp(v[:2])


def test_one_cameras_batch_runs_without_onednn_to_the_same_values_and_leaves_the_users_flag():
    """Below ONEDNN_MIN_BATCH latents the decoder runs PyTorch's own convolutions (faster there): the same g and J
    as the oneDNN path of a larger batch within float32 rounding (another summation order: ~1e-7 relative, checked
    at 1e-5), and the user's oneDNN setting is back after the call, after an error, and never turned on."""
    from bodyschema.models.pixel import ONEDNN_MIN_BATCH, convolutions_for
    q = joint_angles(64, seed=0)
    with one_thread():
        model = tiny_decoder(epochs=2).fit(q, blob_images(q), progress=False)
        z = joint_angles(ONEDNN_MIN_BATCH, seed=3)
        g, jac = model.predict_and_jacobian(z)
        for i in range(len(z)):
            g_i, jac_i = model.predict_and_jacobian(z[i:i + 1])
            torch.testing.assert_close(g_i, g[i:i + 1], rtol=1e-5, atol=1e-6)
            torch.testing.assert_close(jac_i, jac[i:i + 1], rtol=1e-5, atol=1e-5)
            torch.testing.assert_close(model.predict(z[i:i + 1]), g[i:i + 1], rtol=1e-5, atol=1e-6)
    user = torch.backends.mkldnn.enabled
    try:
        with pytest.raises(RuntimeError), convolutions_for(1):
            assert not torch.backends.mkldnn.enabled
            raise RuntimeError("inside")
        assert torch.backends.mkldnn.enabled == user
        torch.backends.mkldnn.enabled = False
        with convolutions_for(ONEDNN_MIN_BATCH):
            assert not torch.backends.mkldnn.enabled, "a user's oneDNN off stays off"
    finally:
        torch.backends.mkldnn.enabled = user



def saved_without(model, key: str, folder):
    """model saved to folder with `key` dropped from its config (as saved before the option existed), loaded back:
    (the value it had, the loaded model)."""
    model.save(folder)
    meta_path = folder / "meta.json"
    meta = json.loads(meta_path.read_text())
    value = meta["config"].pop(key)
    meta_path.write_text(json.dumps(meta))
    return value, load_model(folder)


def test_the_loss_defaults_to_cross_entropy_is_saved_a_save_without_it_loads_as_mse_splat_takes_mse(tmp_path):
    model = TestPixelDecoder().make_model(seed=0)
    assert model.loss == "cross_entropy" and tiny_decoder(loss="mse").loss == "mse"          # the conv sizes' default
    assert tiny_decoder(size="splat").loss == "mse"
    saved, loaded = saved_without(model, "loss", tmp_path / "m")
    z = joint_angles(3, seed=5)
    assert saved == "cross_entropy" and loaded.loss == "mse"
    torch.testing.assert_close(loaded.predict(z), model.predict(z), rtol=0, atol=0)
    with pytest.raises(ValueError, match=r"loss must be one of \['cross_entropy', 'mse'\]. Got 'l1'"):
        tiny_decoder(loss="l1")
    with pytest.raises(ValueError, match=r"loss must be 'mse' for size 'splat'. Got 'cross_entropy'. A sum of blobs"):
        tiny_decoder(size="splat", loss="cross_entropy")


def test_inputs_default_to_products_are_saved_and_a_save_without_them_loads_as_u(tmp_path):
    model = TestPixelDecoder().make_model(seed=0)
    assert model.inputs == "products" and model.net_.fc[0].in_features == 3 ** 2   # no more than the 3^D terms
    with pytest.raises(ValueError, match=r"inputs must be one of \('unit', 'products', 'kinematic'\). Got 'u'"):
        tiny_decoder(inputs="u")
    q = joint_angles(64, seed=0)
    unit = tiny_decoder(inputs="unit").fit(q, blob_images(q), progress=False)
    assert unit.net_.fc[0].in_features == 2
    saved, loaded = saved_without(unit, "inputs", tmp_path / "m")
    z = joint_angles(3, seed=5)
    assert saved == "unit" and loaded.inputs == "unit"
    torch.testing.assert_close(loaded.predict(z), unit.predict(z), rtol=0, atol=0)
    model.save(tmp_path / "p")
    products = load_model(tmp_path / "p")
    torch.testing.assert_close(products.predict(z), model.predict(z), rtol=0, atol=0)   # the learned factors too


def blob_on_black_scores(fit_predict) -> tuple[dict, dict]:
    """A blob covering 2 % of a black image (a small arm in a frame of its whole reach), fitted by each loss.
    fit_predict(q, x, q_val, loss) → predicted images. {loss: median px from the true blob}, {loss: how much the
    predicted image changes with the pose}."""
    q, q_val = joint_angles(256, seed=0), joint_angles(64, seed=1)
    shape = (24, 36)
    x, x_val = blob_images(q, shape, width_px=1.2), blob_images(q_val, shape, width_px=1.2)
    assert float((x > 0.1).float().mean()) < 0.03
    found, varies = {}, {}
    for loss in ("mse", "cross_entropy"):
        pred = fit_predict(q, x, q_val, loss)
        found[loss] = float((peak_px(pred) - peak_px(x_val)).norm(dim=1).median())
        varies[loss] = float(pred.std(dim=0).mean())
    return found, varies


def assert_blob_learned_by_cross_entropy_only(found: dict, varies: dict) -> None:
    assert found["cross_entropy"] <= 2.5 and varies["cross_entropy"] > 0.01, (found, varies)
    assert varies["mse"] < 1e-3 and found["mse"] > 5 * found["cross_entropy"], (found, varies)


def test_pixel_aif_steps_at_2e3_by_cross_entropy_and_at_5e4_by_mse_unless_told():
    def step(size="pixel_aif", **kw):
        return PixelDecoder(ToyPlanarArm().body, "image", HW, size=size, **kw).settings.lr
    assert (step(), step(loss="mse"), step(loss="mse", lr=1e-3)) == (2e-3, 5e-4, 1e-3)
    assert step("lean") == step("lean", loss="mse") == 4e-3                       # lean: one step for both


def test_each_size_has_its_schedule_unless_told():
    """lean decays its larger step over the last 20 % of the epochs (SIZES); the others keep a constant step; an
    explicit schedule wins (tests/models/test_lr_schedule.py: it survives a save and load)."""
    def schedule(size, **kw):
        return PixelDecoder(ToyPlanarArm().body, "image", HW, size=size, **kw).settings.lr_schedule
    assert (schedule("lean"), schedule("pixel_aif"), schedule("splat")) == ("wsd", "constant", "constant")
    assert schedule("lean", lr_schedule="constant") == "constant"
    # a size's preset is merged over lean's: one that did not state its own step and schedule would inherit lean's
    assert all({"lr", "schedule"} <= set(preset) for preset in SIZES.values()), SIZES


@pytest.mark.usefixtures("tiny_threads")
def test_a_small_bright_blob_on_black_is_learned_by_cross_entropy_where_squared_error_goes_dark():
    """The squared error through the sigmoid drives every logit down, σ' vanishes and the output is one dark image
    for every pose (SO-101 at 64×64: README); the cross-entropy's gradient on a logit is σ − x, which does not
    vanish on the blob."""
    def fit_predict(q, x, q_val, loss):
        return tiny_decoder(x.shape[1:], loss=loss, epochs=60).fit(q, x, progress=False).predict(q_val.double())
    assert_blob_learned_by_cross_entropy_only(*blob_on_black_scores(fit_predict))
