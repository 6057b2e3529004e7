"""ONNX export (models/onnx_export.py): every exportable kind runs in onnxruntime and equals the model's own output."""

from __future__ import annotations

import pytest
import torch

from bodyschema.models.onnx_export import OPSET, check_exportable, export_onnx, read_metadata, verify_onnx
from bodyschema.models.scaling import BodySpec

pytest.importorskip("onnxruntime")
pytest.importorskip("onnxscript")
pytestmark = pytest.mark.filterwarnings("ignore:.*LeafSpec.*:FutureWarning")   # torch.export internals


BODY = BodySpec("toy", ("a", "b", "c"), (-1.0, -0.5, 0.0), (1.0, 1.5, 2.0))
IMAGE = (12, 20)          # small images: two ×2 stages of the decoder, a centre crop on the width
TOL = 1e-5


def _data(n: int = 64, seed: int = 0):
    gen = torch.Generator().manual_seed(seed)
    q = BODY.from_unit(torch.rand(n, 3, generator=gen) * 2 - 1)                     # (n, 3) rad
    xyz = torch.stack([q[:, 0].cos() * 300, q[:, 1].sin() * 200 + q[:, 2], q.sum(1)], 1)   # (n, 3) px-sized values
    rows = torch.arange(IMAGE[0])[None, :, None]
    cols = torch.arange(IMAGE[1])[None, None, :]
    centre = (q[:, :1, None] + 1) * 0.5 * IMAGE[1]                                   # (n, 1, 1) a moving bright bar
    image = torch.exp(-((cols - centre) ** 2) / 8.0).expand(n, *IMAGE) * (rows >= 0)     # (n, H, W) in [0, 1]
    return q, xyz, image


def _mdn(mode):
    from bodyschema.models.mdn import MDNModel
    q, xyz, _ = _data()
    return MDNModel(BODY, "ee_pixel", (3,), mode=mode, hidden=(16,), epochs=3).fit(q, xyz, progress=False)


def _pixel(rgb: bool = False, inputs: str = "products"):
    from bodyschema.models.pixel import PixelDecoder
    q, _, image = _data()
    if rgb:                                                           # (n, H, W, 3): the channel axis last
        image = torch.stack([image, 1 - image, image.roll(3, -1)], -1)
    shape = (*IMAGE, 3) if rgb else IMAGE
    return PixelDecoder(BODY, "image", shape, channels=(8, 4), fc_hidden=16, epochs=2, inputs=inputs).fit(
        q, image, progress=False)


def _splat():
    from bodyschema.models.pixel import PixelDecoder
    q, _, image = _data()
    return PixelDecoder(BODY, "image", IMAGE, size="splat", epochs=2).fit(q, image, progress=False)


def _member(decoder):
    from bodyschema.models.multimodal import MultimodalModel
    q, xyz, image = _data()
    model = MultimodalModel(BODY, {"ee_xyz": (3,), "image": IMAGE}, hidden=(16,), fc_hidden=16, channels=(8, 4),
                            epochs=2)
    model.fit(q, {"ee_xyz": xyz, "image": image}, progress=False)
    return model.members["image" if decoder == "pixel" else "ee_xyz"]


def _encoder():
    from bodyschema.models.encoder import ImageEncoder
    q, _, image = _data()
    return ImageEncoder(BODY, "image", IMAGE, channels=(4, 8), fc_hidden=16, epochs=2).fit(q, image, progress=False)


def _gpr(kernel: str = "rbf"):
    from bodyschema.models.gpr import GPRModel
    q, xyz, _ = _data()
    return GPRModel(BODY, "ee_pixel", (3,), adam_steps=5, lbfgs_steps=5, kernel=kernel).fit(q, xyz, progress=False)


KINDS = {"mdn-mean": lambda: _mdn("mean"), "mdn-max": lambda: _mdn("max"), "pixel": _pixel,
         "pixel-rgb": lambda: _pixel(rgb=True), "pixel-unit": lambda: _pixel(inputs="unit"),
         "pixel-kinematic": lambda: _pixel(inputs="kinematic"), "pixel-splat": _splat,
         "multimodal-mlp": lambda: _member("mlp"), "multimodal-pixel": lambda: _member("pixel"),
         "encoder": _encoder, "gpr": _gpr, "gpr-kinematic": lambda: _gpr("kinematic")}


UNITS = {"mdn-mean": "in px", "mdn-max": "in px", "pixel": "in intensity [0, 1]", "pixel-rgb": "in intensity [0, 1]",
         "pixel-unit": "in intensity [0, 1]", "pixel-kinematic": "in intensity [0, 1]",
         "pixel-splat": "in intensity [0, 1]",
         "multimodal-mlp": "in m", "multimodal-pixel": "in intensity [0, 1]", "encoder": "rad", "gpr": "in px",
         "gpr-kinematic": "in px"}


@pytest.mark.parametrize("kind", list(KINDS))
def test_export_runs_in_onnxruntime_and_equals_the_model(kind, tmp_path):
    model = KINDS[kind]()
    path = export_onnx(model, tmp_path / f"{kind}.onnx")
    error = verify_onnx(model, path, n=33)        # an odd batch: the batch axis is dynamic, not the example's 2
    assert error < TOL, f"{kind}: max |onnx − model| = {error:.3g}"
    meta = read_metadata(path)
    assert meta["opset"] == str(OPSET) == meta["bodyschema.opset"]
    assert meta["bodyschema.kind"] == model.kind and meta["bodyschema.modality"] == model.modality
    assert meta["bodyschema.output"].endswith(UNITS[kind]), meta["bodyschema.output"]
    assert BodySpec.from_dict(__import__("json").loads(meta["bodyschema.body"])) == BODY


def test_the_scaling_is_inside_the_graph(tmp_path):
    """Feeding rad gives the model's output; feeding the unit-box values (what the bare network takes) does not."""
    import onnxruntime as ort

    model = _mdn("mean")
    path = export_onnx(model, tmp_path / "mdn.onnx")
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    q = torch.tensor([[0.9, 1.4, 1.9], [-0.9, -0.4, 0.1]], dtype=torch.float64)     # rad, far from their unit values
    (x,) = session.run(None, {"q": q.numpy()})
    torch.testing.assert_close(torch.from_numpy(x), model.predict(q), rtol=0, atol=TOL)
    (bare,) = session.run(None, {"q": BODY.to_unit(q).numpy()})
    assert not torch.allclose(torch.from_numpy(bare), model.predict(q), atol=1e-2)


def test_kinds_without_a_tensor_graph_are_refused_with_the_reason():
    from bodyschema.models.analytic import AnalyticModel

    with pytest.raises(ValueError, match="model kind must be one of .*Got 'analytic'.*MJCF"):
        check_exportable(AnalyticModel("planar2", "ee_xyz"))


def test_an_unfitted_model_is_refused(tmp_path):
    from bodyschema.models.mdn import MDNModel

    with pytest.raises(ValueError, match="fitted"):
        export_onnx(MDNModel(BODY, "ee_xyz", (3,)), tmp_path / "x.onnx")
