"""The amortized image encoder x → z on blob images of the toy arm: training, encode's inputs and errors,
persistence in the models' format, and that perception refuses it (it is not a SensoryModel)."""

import json

import numpy as np
import pytest
import torch

from bodyschema.errors import NotFittedError
from bodyschema.models import SensoryModel, load_model
from bodyschema.models.encoder import MAX_MAP, SMALL_SIDE, ImageEncoder, channels_for, pool_for
from tests.models.test_pixel import blob_images, one_thread
from tests.toy_models import ToyPlanarArm

SHAPE = (16, 24)
TINY = dict(channels=(8, 8), fc_hidden=32, epochs=40, batch_size=32, lr=3e-3, patience=100)


def elbow_up_angles(n: int, seed: int) -> torch.Tensor:
    """Poses whose end effector fixes them (one elbow sign, so no two poses make the same blob). (n, 2) rad"""
    gen = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 2, generator=gen)
    return torch.stack([u[:, 0] * 3.0 - 1.5, u[:, 1] * 1.7 + 0.3], -1)


def tiny_encoder(shape=SHAPE, **overrides) -> ImageEncoder:
    return ImageEncoder(ToyPlanarArm().body, "image", shape, **{**TINY, **overrides})


_FITTED = {}


@pytest.fixture
def encoder() -> ImageEncoder:
    if "encoder" not in _FITTED:
        q, q_val = elbow_up_angles(384, seed=0), elbow_up_angles(96, seed=1)
        with one_thread():
            _FITTED["encoder"] = tiny_encoder().fit(q, blob_images(q, SHAPE, width_px=2.0), seed=0, progress=False,
                                                    val=(q_val, blob_images(q_val, SHAPE, width_px=2.0)))
    return _FITTED["encoder"]


def uint8_images(q: torch.Tensor) -> torch.Tensor:
    return (blob_images(q, SHAPE, width_px=2.0) * 255).round().to(torch.uint8)


def test_training_learns_the_joint_angles(encoder):
    q = elbow_up_angles(96, seed=1)
    err = encoder.encode(blob_images(q, SHAPE, width_px=2.0)) - q                  # (96, 2) rad
    rmse = err.pow(2).mean(0).sqrt()                                               # (2,) per joint
    spread = q.std(0)                                                              # RMSE of guessing the mean
    assert (rmse < 0.3 * spread).all(), f"per-joint RMSE {rmse} should be far below the spread {spread}"
    assert encoder.fit_info_["best_loss"] < 0.1


def test_encode_accepts_uint8_float_and_numpy_and_stays_in_the_body_range(encoder):
    q = elbow_up_angles(6, seed=2)
    x8 = uint8_images(q)                                                           # (6, 16, 24) uint8
    z8 = encoder.encode(x8)
    assert z8.shape == (6, 2) and z8.dtype == torch.float32
    torch.testing.assert_close(encoder.encode(x8.float() / 255), z8, rtol=0, atol=0)
    torch.testing.assert_close(encoder.encode(x8.numpy()), z8, rtol=0, atol=0)
    torch.testing.assert_close(encoder.encode(x8[..., None]), z8, rtol=0, atol=0)   # (N, H, W, 1) for gray
    z64 = encoder.encode(x8.double() / 255)
    assert z64.dtype == torch.float64 and torch.allclose(z64, z8.double(), atol=1e-6)
    body = encoder.body
    saturated = encoder.encode(torch.ones(2, *SHAPE))                              # nothing like training data
    assert (saturated >= torch.tensor(body.q_low)).all() and (saturated <= torch.tensor(body.q_high)).all()


def test_batched_encode_equals_one_image_at_a_time(encoder):
    x = uint8_images(elbow_up_angles(5, seed=3))
    rows = torch.cat([encoder.encode(x[i:i + 1]) for i in range(5)])
    torch.testing.assert_close(rows, encoder.encode(x), rtol=1e-6, atol=1e-6)


def test_same_seed_gives_the_same_encoder():
    q = elbow_up_angles(64, seed=0)
    x = uint8_images(q)
    with one_thread():
        a, b = (tiny_encoder(epochs=2).fit(q, x, seed=3, progress=False) for _ in range(2))
    torch.testing.assert_close(a.encode(x), b.encode(x), rtol=0, atol=0)


def test_save_load_round_trip_in_the_models_format(encoder, tmp_path):
    encoder.save(tmp_path / "enc")
    meta = json.loads((tmp_path / "enc" / "meta.json").read_text())
    assert meta["kind"] == "encoder" and meta["modality"] == "image" and meta["output_shape"] == [2]
    assert meta["config"]["image_shape"] == list(SHAPE)
    torch.load(tmp_path / "enc" / "state.pt", weights_only=True)                   # tensors only
    loaded = load_model(tmp_path / "enc")
    assert isinstance(loaded, ImageEncoder) and loaded.body == encoder.body
    assert ImageEncoder.load(tmp_path / "enc").channels == encoder.channels
    x = uint8_images(elbow_up_angles(4, seed=4))
    torch.testing.assert_close(loaded.encode(x), encoder.encode(x), rtol=0, atol=0)


def test_perception_refuses_an_encoder_by_name(encoder):
    from bodyschema.aif.free_energy import check_models

    assert not isinstance(encoder, SensoryModel)
    with pytest.raises(TypeError, match=r"models\[0\] must be a SensoryModel .*Got 'ImageEncoder'"):
        check_models([encoder])


def test_to_cpu_is_a_no_op_that_keeps_outputs_bit_for_bit(encoder):
    x = uint8_images(elbow_up_angles(3, seed=5))
    before = encoder.encode(x)
    assert encoder.to("cpu") is encoder
    torch.testing.assert_close(encoder.encode(x), before, rtol=0, atol=0)
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match=r"device must be 'cpu' or an available CUDA device. Got 'cuda'"):
            encoder.to("cuda")


@pytest.mark.parametrize("images, error, message", [
    (torch.zeros(2, 16, 20, dtype=torch.uint8), ValueError, r"images must be of shape \(N, 16, 24\): the size"),
    (torch.zeros(2, 16, 24, 3, dtype=torch.uint8), ValueError, r"images must be 1-channel, of shape \(N, 16, 24\)"),
    (torch.zeros(16, 24, dtype=torch.uint8), ValueError, r"Add a batch axis with images\[None\]"),
    (torch.zeros(2, 16, 24, dtype=torch.int64), TypeError, r"images.dtype must be uint8 \(0–255\) or float"),
    (torch.full((2, 16, 24), 255.0), ValueError, r"images must be finite intensities in \[0, 1\]"),
    (np.zeros((2, 16, 24), dtype=object), TypeError, r"images.dtype must be"),
    ([[0.0]], TypeError, r"images must be a torch.Tensor or numpy array"),
])
def test_bad_images_raise_the_house_error(encoder, images, error, message):
    with pytest.raises(error, match=message):
        encoder.encode(images)


def test_unfitted_and_bad_settings_raise():
    with pytest.raises(NotFittedError):
        tiny_encoder().encode(torch.zeros(1, *SHAPE))
    with pytest.raises(NotFittedError):
        tiny_encoder().save("unused")
    with pytest.raises(ValueError, match=r"image_shape must be at least 8 px high and wide for 3 stride-2 stages"):
        tiny_encoder((6, 24), channels=(4, 4, 4))._factory()
    q = elbow_up_angles(8, seed=0)
    with pytest.raises(ValueError, match=r"x must be of shape \(N, 16, 24\)"):
        tiny_encoder().fit(q, torch.zeros(8, 16, 20), progress=False)


@pytest.mark.parametrize("shape, stages", [((56, 80), 3), ((64, 64), 3), ((32, 32, 3), 3), ((96, 96), 4),
                                           ((128, 128), 4), ((256, 200), 5)])
def test_stages_bring_the_last_map_to_ten_pixels_and_keep_the_shipped_arms_three(shape, stages):
    # A 128×128 image through three stages left 16×16×64 inputs to the tanh head, which saturated at ±1 in the first
    # epoch on SO-101 (RMSE twice a constant guess); the rule adds stages for large images only (read unpooled here).
    encoder = ImageEncoder(ToyPlanarArm().body, "image", shape, pool=1)
    assert encoder.channels == channels_for(shape) and len(encoder.channels) == stages
    h, w = shape[0] >> stages, shape[1] >> stages
    assert max(h, w) <= MAX_MAP and encoder._factory().head[0].in_features == encoder.channels[-1] * h * w
    assert ImageEncoder(ToyPlanarArm().body, "image", shape, channels=(8, 8)).channels == (8, 8)   # given: as is


@pytest.mark.parametrize("shape, lr", [((56, 80), 2e-3), ((64, 64), 2e-3), ((80, 80, 3), 2e-3), ((96, 96), 5e-4),
                                       ((128, 128), 5e-4)])
def test_the_step_follows_the_image_size_and_a_given_one_is_kept(shape, lr):
    # 2e-3 collapsed the UR5's 128×128 encoder (read unpooled) in its first epoch (tanh at ±1, loss flat at 4/3)
    assert ImageEncoder(ToyPlanarArm().body, "image", shape, pool=1).settings.lr == lr
    assert ImageEncoder(ToyPlanarArm().body, "image", shape, lr=1e-3).settings.lr == 1e-3
    assert ImageEncoder(ToyPlanarArm().body, "image", shape, pool=1)._config()["lr"] == lr   # saved: the step used


@pytest.mark.parametrize("shape, pool", [((56, 80), 1), ((64, 64), 1), ((80, 80, 3), 1), ((96, 96), 2),
                                         ((128, 128), 2), ((256, 200), 4), ((1024, 96), 16)])
def test_a_large_image_is_pooled_to_the_small_sides_and_read_by_their_stages_and_step(shape, pool):
    # SO-101's 128×128 read pooled to 64×64: the same or lower held-out error at a quarter of the time (encoder.py)
    encoder = ImageEncoder(ToyPlanarArm().body, "image", shape)
    seen = (shape[0] // pool, shape[1] // pool, *shape[2:])
    assert encoder.pool == pool_for(shape) == pool
    assert max(seen[:2]) <= SMALL_SIDE and (pool == 1 or SMALL_SIDE < max(seen[:2]) * 2)   # the least such pool
    assert encoder.channels == channels_for(seen) and encoder.settings.lr == 2e-3
    assert encoder._config()["pool"] == pool


def test_the_pooled_net_reads_what_the_same_net_reads_from_a_pooled_image():
    big, small = ImageEncoder(ToyPlanarArm().body, "image", (32, 48), pool=2, channels=(8, 8), fc_hidden=16), \
        ImageEncoder(ToyPlanarArm().body, "image", SHAPE, pool=1, channels=(8, 8), fc_hidden=16)
    net_big, net_small = big._factory(), small._factory()
    net_small.load_state_dict(net_big.state_dict())                     # the pooling holds no weights
    x = torch.rand(5, 32, 48, generator=torch.Generator().manual_seed(0))
    pooled = torch.nn.functional.avg_pool2d(x[:, None], 2)[:, 0]
    torch.testing.assert_close(net_big(x), net_small(pooled), rtol=1e-6, atol=1e-6)   # float32, same kernels


def test_an_encoder_saved_before_pooling_loads_unpooled(encoder, tmp_path):
    encoder.save(tmp_path / "enc")
    meta_path = tmp_path / "enc" / "meta.json"
    meta = json.loads(meta_path.read_text())
    assert meta["config"].pop("pool") == 1
    meta_path.write_text(json.dumps(meta))
    loaded = load_model(tmp_path / "enc")
    x = uint8_images(elbow_up_angles(4, seed=4))
    assert loaded.pool == 1
    torch.testing.assert_close(loaded.encode(x), encoder.encode(x), rtol=0, atol=0)


def test_a_pool_that_leaves_no_pixel_is_the_house_error():
    with pytest.raises(ValueError, match=r"pool must be an int ≥ 1 that leaves pixels of the \(16, 24\) image. Got 32"):
        ImageEncoder(ToyPlanarArm().body, "image", SHAPE, pool=32)
