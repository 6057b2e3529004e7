"""Amortized image encoder x → z (kind "encoder"): one forward pass from a camera image to joint angles in rad.

The inverse direction of the sensory models: where perception searches for the z whose predicted image
matches the observation, the encoder regresses z directly (a starting belief for perception, or a baseline for
it). It is *not* a `SensoryModel` (no predict / jacobian / vjp / precision), so perception refuses it; it shares
their persistence (`meta.json` + `state.pt` read with `weights_only=True`, `load_model`), their estimator
conventions (`get_params`, `clone`, `repr`: `contract.Estimator`) and their body spec, so callers check
`encoder.body` against the robot. Net: an average pooling that brings a large image to at most SMALL_SIDE px a
side (`pool_for`), stride-2 convolutions (each halves H and W), a fully connected head, tanh to the unit box and the
body's `from_unit` to rad, so an estimate never leaves the scaled joint range. Trained by the squared error in that
unit space (every joint weighs the same, whatever its range).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from bodyschema.errors import must_be
from bodyschema.models._nn_fit import TrainSettings, build, check_fit_data, check_val, train
from bodyschema.models._nn_model import NetHolder
from bodyschema.models.contract import BaseSensoryModel, check_body, register_kind
from bodyschema.models.estimator import Estimator
from bodyschema.models.pixel import fast_layout, image_layout
from bodyschema.models.scaling import IMAGE_SCALE, BodySpec

FLOATS = (torch.float32, torch.float64)
BASE_CHANNELS = (16, 32, 64)   # nao_arm's 56×80 → 28×40×16 → 14×20×32 → 7×10×64
MAX_MAP = 10                   # px a side of the last feature map the default stages reach
# Adam's step by image size (None: `lr_for`). At 2e-3 the UR5's 128×128 encoder collapsed in its first epoch (the tanh
# head at ±1 for every image, the loss flat at 4/3, held-out RMSE 207°: twice a constant guess); at 5e-4 it trained
# (93°), and SO-101's and the Panda URDF's 128×128 encoders came out the same at either step (52.2 vs 52.4°, 77.5 vs
# 76.6°). Up to 80 px a side (nao_arm's 56×80, the 64×64 arms) the step measured there stays.
LR_SMALL, LR_LARGE, SMALL_SIDE = 2e-3, 5e-4, 80
# A large image is read average-pooled to at most SMALL_SIDE px a side (`pool_for`); the stages and the step then
# follow the pooled size. Measured on SO-101's 128×128 images (seed 0, 20 epochs, held-out mean |error| per joint):
# 3 000 images 14.8, 19.5, 25.1, 45.1° read whole (231 s) against 12.5, 16.5, 22.6, 45.9° pooled to 64×64 (58 s);
# 6 000 images 8.4, 11.1, 18.6, 41.3° (451 s) against 8.3, 11.1, 17.9, 35.7° (115 s). The arm covers 2 % of that
# image: the full resolution bought nothing the encoder used, and cost 4× the time that more images put to use.
CHUNK = 512   # images per forward in `encode`


class EncoderNet(nn.Module):
    """image (B, H, W) or (B, H, W, C) in [0, 1] → u (B, Dz) in (-1, 1)."""

    def __init__(self, latent_dim: int, image_shape: tuple[int, ...], channels: tuple[int, ...], fc_hidden: int,
                 pool: int = 1):
        super().__init__()
        h, w, c = image_layout(image_shape)
        self.pool = nn.AvgPool2d(pool) if pool > 1 else nn.Identity()     # (h, w) → (h // pool, w // pool)
        h, w, stages = h // pool, w // pool, []
        for a, b in zip((c, *channels[:-1]), channels):
            stages += [nn.Conv2d(a, b, 4, stride=2, padding=1), nn.ELU()]   # (h, w) → (h // 2, w // 2)
            h, w = h // 2, w // 2
        if min(h, w) < 1:
            raise ValueError(must_be("image_shape", f"at least {2 ** len(channels)} px high and wide for "
                                                    f"{len(channels)} stride-2 stages", tuple(image_shape),
                                     "Use fewer `channels` for small images."))
        self.conv = nn.Sequential(*stages)
        self.head = nn.Sequential(nn.Linear(channels[-1] * h * w, fc_hidden), nn.ELU(),
                                  nn.Linear(fc_hidden, latent_dim), nn.Tanh())

    def forward(self, x):
        if x.ndim == 3:
            x = x[..., None]                                             # (B, H, W, 1)
        y = self.conv(self.pool(x.permute(0, 3, 1, 2)))                  # (B, C_n, h, w); NHWC memory: free
        return self.head(y.flatten(1))                                   # (B, Dz)


def pool_for(image_shape: tuple[int, ...]) -> int:
    """The default input pooling: the least power of 2 that brings the image to SMALL_SIDE px a side or less (1 for
    nao_arm's 56×80 and the 64×64 arms, 2 for 128×128)."""
    h, w, _ = image_layout(image_shape)
    pool = 1
    while max(h, w) // pool > SMALL_SIDE:
        pool *= 2
    return pool


def pooled(image_shape: tuple[int, ...], pool: int) -> tuple[int, ...]:
    """The image shape the stages see after pooling by `pool`."""
    h, w, c = image_layout(image_shape)
    return (h // pool, w // pool, c)


def lr_for(image_shape: tuple[int, ...]) -> float:
    """The default Adam step: LR_SMALL up to SMALL_SIDE px a side, LR_LARGE above (see their comment)."""
    h, w, _ = image_layout(image_shape)
    return LR_SMALL if max(h, w) <= SMALL_SIDE else LR_LARGE


def channels_for(image_shape: tuple[int, ...]) -> tuple[int, ...]:
    """The default stages: BASE_CHANNELS, then one more stride-2 stage of 64 while the last map is wider than MAX_MAP
    px a side (nao_arm's 56×80 and 64×64 keep three). Measured on SO-101's 128×128 images (3 000, seed 0): with three
    stages the head's 16×16×64 = 16 384 inputs drove its tanh to ±1 within the first epoch, where it stayed (held-out
    RMSE 134°, a constant guess 63°); with four (8×8) it trained (53° after 5 epochs, still falling)."""
    h, w, _ = image_layout(image_shape)
    channels = list(BASE_CHANNELS)
    while max(h, w) >> len(channels) > MAX_MAP:
        channels.append(BASE_CHANNELS[-1])
    return tuple(channels)


@register_kind
class ImageEncoder(NetHolder, Estimator):
    kind = "encoder"
    exports_onnx = convolutional = encodes = True

    def __init__(self, body: BodySpec, modality: str, image_shape: tuple[int, ...], *,   # the data's (H, W[, C])
                 channels: tuple[int, ...] | None = None,   # None: `channels_for` the pooled image
                 fc_hidden: int = 128,
                 pool: int | None = None,                   # None: `pool_for(image_shape)`
                 epochs: int = 100, batch_size: int = 64,
                 lr: float | None = None,                   # None: `lr_for` the pooled image
                 patience: int = 10,
                 weight_decay: float = 0.0, lr_schedule: str = "constant"):
        self.body, self.latent_dim, self.modality = check_body(body), body.latent_dim, modality
        self.image_shape = tuple(int(s) for s in image_shape)
        self.input_shape = self.image_shape                  # per-sample input x (the pyfunc's signature)
        self.output_shape = (self.latent_dim,)               # per-sample output z, rad
        image_layout(self.image_shape)
        self.pool = pool_for(self.image_shape) if pool is None else pool
        seen = pooled(self.image_shape, self.pool) if isinstance(self.pool, int) and self.pool >= 1 else (0, 0)
        if min(seen[:2]) < 1:
            raise ValueError(must_be("pool", f"an int ≥ 1 that leaves pixels of the {self.image_shape} image", pool))
        channels = channels_for(seen) if channels is None else channels
        if not channels or min(channels) < 1 or fc_hidden < 1:
            raise ValueError(must_be("channels and fc_hidden", "a non-empty tuple of positive ints and > 0",
                                     (channels, fc_hidden)))
        self.channels, self.fc_hidden = tuple(channels), fc_hidden
        lr = lr_for(seen) if lr is None else lr
        self.settings = TrainSettings(epochs, batch_size, lr, patience, weight_decay, lr_schedule)
        self.fit_info_: dict = {}

    # ---- fit ------------------------------------------------------------------------------------------
    def fit(self, q, x, *, seed: int = 0, val=None, on_epoch=None, progress: bool = False, checkpoint=None,
            device: str = "cpu", mixed_precision: bool = False):
        """Train on joint angles q (N, Dz) rad and their images x (N, *image_shape) by the squared error of the
        unit-box joint angles, on `device`; self. Same argument order as the sensory models (q, x)."""
        q, x = check_fit_data(q, x, self.latent_dim, self.image_shape)      # (N, Dz), (N, *image) in [0, 1]
        val = check_val(val, self.latent_dim, self.image_shape)
        gen = torch.Generator().manual_seed(seed)
        net = fast_layout(build(self._factory, gen))
        to_unit = self.body.to_unit
        self.fit_info_ = train(net, _unit_mse, (x, to_unit(q)), self.settings, gen,
                               val=(val[1], to_unit(val[0])) if val is not None else None, on_epoch=on_epoch,
                               progress=progress, checkpoint=checkpoint, desc="fit encoder", device=device,
                               mixed_precision=mixed_precision)
        self._set_net(net)
        return self

    def _factory(self) -> EncoderNet:
        return EncoderNet(self.latent_dim, self.image_shape, self.channels, self.fc_hidden, self.pool)

    # ---- inference ------------------------------------------------------------------------------------
    def encode(self, images) -> torch.Tensor:
        """Joint angles of the robot in `images`. (N, *image_shape) uint8 0–255 or float in [0, 1], torch or
        numpy → (N, Dz) rad on the images' device; float32 (float64 for float64 images), computed in float32."""
        self._require_fitted()
        x = self._check_images(images)                                     # (N, *image_shape)
        out_dtype = x.dtype if x.dtype in FLOATS else torch.float32
        scale = IMAGE_SCALE if x.dtype == torch.uint8 else 1.0
        with torch.no_grad():   # in chunks: activations of a whole dataset would not fit in memory
            u = torch.cat([self.net_(x[i:i + CHUNK].to(self.device, torch.float32) / scale)
                           for i in range(0, len(x), CHUNK)])               # (N, Dz) in (-1, 1)
        return self.body.from_unit(u.to(x.device, out_dtype))           # (N, Dz) rad

    # ---- validation -----------------------------------------------------------------------------------
    def _check_images(self, images) -> torch.Tensor:
        if not isinstance(images, (torch.Tensor, np.ndarray)):
            raise TypeError(must_be("images", "a torch.Tensor or numpy array", type(images).__name__))
        if str(images.dtype).removeprefix("torch.") not in ("uint8", "float32", "float64"):
            raise TypeError(must_be("images.dtype", "uint8 (0–255) or float32/float64 in [0, 1]", images.dtype))
        x = torch.from_numpy(np.ascontiguousarray(images)) if isinstance(images, np.ndarray) else images
        want, h, w = self.image_shape, *self.image_shape[:2]
        c = want[2] if len(want) == 3 else 1
        shape = f"(N, {', '.join(map(str, want))})"
        if tuple(x.shape[:2]) == (h, w) and x.ndim in (2, 3):
            raise ValueError(must_be("images", f"a batch of shape {shape}", tuple(x.shape),
                                     "Add a batch axis with images[None] for one image."))
        if x.ndim not in (3, 4) or tuple(x.shape[1:3]) != (h, w):
            raise ValueError(must_be("images", f"of shape {shape}: the size the encoder was trained on",
                                     tuple(x.shape), "Render with the training camera."))
        if (x.shape[3] if x.ndim == 4 else 1) != c:
            raise ValueError(must_be("images", f"{c}-channel, of shape {shape}", tuple(x.shape),
                                     "Use the colour mode (grayscale or RGB) the encoder was trained on."))
        x = x.reshape(len(x), *want)                                        # (N, H, W, 1) ↔ (N, H, W) for C = 1
        if x.dtype in FLOATS and not (torch.isfinite(x).all() and x.min() >= 0 and x.max() <= 1):
            raise ValueError(must_be("images", "finite intensities in [0, 1] (or uint8 0–255)",
                                     f"values in [{float(x.min()):.3g}, {float(x.max()):.3g}]"))
        return x

    # ---- persistence: the models' format, so `load_model` and the registry return an encoder -------------
    def save(self, path) -> None:
        BaseSensoryModel.save(self, path)

    @classmethod
    def load(cls, path) -> "ImageEncoder":
        return BaseSensoryModel.load(path)

    def _config(self) -> dict:
        return {"image_shape": list(self.image_shape), "channels": list(self.channels), "fc_hidden": self.fc_hidden,
                "pool": self.pool,
                "epochs": self.settings.epochs, "batch_size": self.settings.batch_size, "lr": self.settings.lr,
                "patience": self.settings.patience, "weight_decay": self.settings.weight_decay,
                "lr_schedule": self.settings.lr_schedule}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        config = {"pool": 1, **config, "channels": tuple(config["channels"])}   # saved before pooling: none
        model = cls(body, modality, tuple(config.pop("image_shape")), **config)
        model._restore_net(lambda: fast_layout(model._factory()), state)
        return model


def _unit_mse(net: nn.Module, x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """Mean squared error of the unit-box joint angles. x (B, *image), u (B, Dz)."""
    return (net(x) - u).pow(2).mean()
