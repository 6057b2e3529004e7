"""ONNX export of a fitted model: joint angles in rad in, the sensory prediction out, the scaling inside the graph.

The exported graph is a small pure-torch module (`PredictGraph`) that calls the model's own computation, not the
public wrapper: the wrapper's edge checks (`isfinite`, shape and dtype errors, device moves) are what
`torch.export` cannot trace, while the hooks behind them are plain tensor code. So the graph holds
    rad → [-1, 1] (the body's `to_unit`) → network (or the GP's k(u, X) α) → output de-standardization
with no second copy of any of it, and `verify_onnx` checks it against the wrapper's `predict` with onnxruntime.

Kinds: a model class that declares `exports_onnx` (models/capabilities.py) is exported: a network (`network`:
"mdn", "pixel", a "multimodal" member) through its `_outputs`, any other (the "gpr" posterior mean: the RBF kernel
against the cached training inputs and α, a few matmuls and one exp) through its `_predict`, each mapping
q (B, Dz) rad → x (B, *out); an encoder (`encodes`) maps images (B, H, W[, C]) in [0, 1] → q (B, Dz) rad.
Not exportable: "analytic" (MuJoCo's forward kinematics, no tensor graph) and "sklearn-gpr" (scikit-learn
computes its mean in numpy).

dtype: float64 graphs for vector models (error vs `predict` ~1e-12); float32 for `convolutional` models,
because onnxruntime's CPU provider has no float64 Conv / ConvTranspose kernels. Their weights are float32
anyway; the float32 graph rounds differently from torch by ~1e-7 relative, far below 1e-5 on (0, 1) intensities.
"""

from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from bodyschema.base import modalities
from bodyschema.errors import must_be

OPSET = 18                              # onnxruntime ≥ 1.14 runs it; torch's exporter targets ≥ 18
TOLERANCE = 1e-5                        # max |onnxruntime − model| accepted (output units; rad for an encoder)
CHECK_INPUTS = 64                       # seeded inputs of that check
FORMAT = "bodyschema-onnx"              # the kind of output its marker names (base/outputs.py)


class PredictGraph(nn.Module):
    """q (B, Dz) rad → x (B, *output_shape), by the model's hooks (networks: `_outputs` on its weights)."""

    def __init__(self, model, dtype: torch.dtype):
        super().__init__()
        self.model = [model]                            # a list: keeps the wrapper out of the module tree
        self.net = model._net(dtype) if model.network else None   # registered: weights → initializers

    def forward(self, q):
        model = self.model[0]
        if self.net is None:                            # gpr: closed form in float64 (its own `_predict`)
            return model._predict(q).to(q.dtype)
        return model._outputs(self.net, model.body.to_unit(q))


class EncodeGraph(nn.Module):
    """images (B, H, W[, C]) in [0, 1] → q (B, Dz) rad: the encoder's network, then the body's `from_unit`."""

    def __init__(self, encoder):
        super().__init__()
        self.body = encoder.body
        self.net = encoder.net_

    def forward(self, x):
        return self.body.from_unit(self.net(x))


def _why_not(model) -> tuple[str, str]:
    """(what was given, the class's `onnx_hint`) for a model that does not declare `exports_onnx`."""
    members = getattr(model, "has_members", False)          # named by its class: its members have its kind
    given = type(model).__name__ if members else getattr(model, "kind", type(model).__name__)
    return given, getattr(model, "onnx_hint", "")


def graph_dtype(model) -> torch.dtype:
    return torch.float32 if model.convolutional else torch.float64


def exportable_kinds() -> list[str]:
    """The kinds whose saved class declares `exports_onnx` (imports every kind's module: for messages only)."""
    from bodyschema.models import kinds

    return [name for name in kinds.KINDS if _declares_export(name)]


def _declares_export(name: str) -> bool:
    from bodyschema.models import kinds

    try:
        return kinds.saved_class(name).exports_onnx
    except ImportError:                 # a kind whose module is broken exports nothing
        return False


def check_exportable(model) -> None:
    if not getattr(model, "exports_onnx", False):     # any object without the declaration is refused by name
        raise ValueError(must_be("model kind", f"one of {exportable_kinds()} to export ONNX", *_why_not(model)))
    if not model.is_fitted:
        raise ValueError(must_be("model", "fitted", "a model without learned state", "Call `fit` first."))


def export_onnx(model, out: str | Path, *, opset: int = OPSET, overwrite: bool = False) -> Path:
    """Write `out` (.onnx, one file): input "q" (B, Dz) rad ("image" for an encoder), output "x" ("q"), a dynamic
    batch axis, and metadata (opset, kind, modality, body, shapes, units, the check) in the file's `metadata_props`.

    The graph is run in onnxruntime against the model before anything is written; `out` appears only once that
    check passed (base/outputs.py: beside it, then renamed; --overwrite replaces only a previous ONNX export)."""
    import onnx

    from bodyschema.base.outputs import write_atomically

    check_exportable(model)
    check_opset(opset)
    proto = _export_proto(model, opset)
    written = model_opset(proto)
    if written != opset:        # torch builds opset 18 and converts down; the conversion can fail (then stays 18)
        raise ValueError(must_be("--opset", "an opset this graph converts to", opset,
                                 f"The exporter could not convert it and gave opset {written}: pass --opset "
                                 f"{written}. Nothing was written."))
    error = verify_onnx(model, proto.SerializeToString())
    if not error <= TOLERANCE:
        raise FloatingPointError(must_be("the exported graph", f"equal to the model within {TOLERANCE:g}",
                                         f"max |error| {error:.3g}", "Nothing was written; report it."))
    onnx.helper.set_model_props(proto, metadata(model, written, error))
    onnx.checker.check_model(proto)
    source = getattr(model, "provenance", None) or {"kind": model.kind, "modality": model.modality}
    return write_atomically(out, lambda tmp: onnx.save_model(proto, str(tmp)), overwrite, kind=FORMAT,
                            need_bytes=proto.ByteSize(), source=source)


def supported_opsets() -> range:
    """The opsets the installed exporter accepts: torch's ONNX range, capped by what the installed onnx knows."""
    import onnx
    from torch.onnx import _constants  # torch's own bounds of `opset_version` (no public name for them)

    return range(_constants.ONNX_MIN_OPSET, min(_constants.ONNX_MAX_OPSET, onnx.defs.onnx_opset_version()) + 1)


def check_opset(opset: int) -> None:
    opsets = supported_opsets()
    if not isinstance(opset, int) or opset not in opsets:
        raise ValueError(must_be("--opset", f"an integer in [{opsets.start}, {opsets.stop - 1}] (the installed "
                                 "exporter's range)", opset, f"The default, {OPSET}, is what torch builds."))


def _export_proto(model, opset: int):
    """The model's graph as an in-memory ONNX ModelProto (torch's dynamo exporter)."""
    graph, example, names = _graph(model)
    # torch's exporter warns once per torchvision operator it cannot register (torchvision is not a dependency);
    # below opset 18 it and onnxscript warn of the down-conversion, with a traceback when it fails: `export_onnx`
    # compares the opset it got with the one asked and says so in one line
    for name in ("torch.onnx._internal.exporter._registration", "torch.onnx._internal.exporter._compat",
                 "onnxscript.version_converter"):
        logging.getLogger(name).setLevel(logging.ERROR)
    with torch.no_grad(), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*LeafSpec.*", category=FutureWarning)   # torch.export's own
        program = torch.onnx.export(graph, (example,), dynamo=True, opset_version=opset, verbose=False,
                                    input_names=[names[0]], output_names=[names[1]], optimize=True,
                                    dynamic_shapes=({0: torch.export.Dim("batch", min=1)},), external_data=False)
    return program.model_proto


def model_opset(proto) -> int:
    """The default-domain opset a ModelProto really imports."""
    return next(o.version for o in proto.opset_import if o.domain in ("", "ai.onnx"))


def _graph(model) -> tuple[nn.Module, torch.Tensor, tuple[str, str]]:
    """(module, an example input of batch 2, (input name, output name))."""
    dtype = graph_dtype(model)
    if model.encodes:
        return EncodeGraph(model).eval(), torch.rand(2, *model.image_shape, dtype=torch.float32), ("image", "q")
    z = model.body.from_unit(torch.zeros(2, model.latent_dim, dtype=dtype))        # (2, Dz) mid-range, rad
    return PredictGraph(model, dtype).eval(), z, ("q", "x")


def metadata(model, opset: int, error: float) -> dict[str, str]:
    """What a consumer needs beside the graph: units, shapes, joint order, where the numbers came from, and the
    check it passed (`error`: max |onnxruntime − model| over CHECK_INPUTS inputs)."""
    encoder = model.encodes
    dtype = "float32" if encoder else str(graph_dtype(model)).removeprefix("torch.")
    return {"bodyschema.opset": str(opset), "bodyschema.kind": model.kind, "bodyschema.modality": model.modality,
            "bodyschema.body": json.dumps(model.body.to_dict()), "bodyschema.dtype": dtype,
            "bodyschema.input": (f"image (B, {', '.join(map(str, model.image_shape))}) {dtype} in [0, 1]" if encoder
                                 else f"q (B, {model.latent_dim}) {dtype} rad, joints {list(model.body.joint_names)}"),
            "bodyschema.output": (f"q (B, {model.latent_dim}) rad" if encoder
                                  else f"x (B, {', '.join(map(str, model.output_shape))}) {model.modality} in "
                                       f"{modalities.unit(model.modality, 'its dataset units')}"),
            "bodyschema.source": json.dumps(getattr(model, "provenance", None) or {}),   # registry name, version, sha
            "bodyschema.check": f"onnxruntime vs the model: max |error| {error:.3g} over {CHECK_INPUTS} inputs "
                                f"(tolerance {TOLERANCE:g})"}


def read_metadata(path: str | Path) -> dict[str, str]:
    """The `metadata_props` of an exported file, plus its opset as "opset"."""
    import onnx

    proto = onnx.load(str(path), load_external_data=False)
    props = {p.key: p.value for p in proto.metadata_props}
    props["opset"] = str(model_opset(proto))
    return props


def verify_onnx(model, graph: str | Path | bytes, *, n: int = CHECK_INPUTS, seed: int = 0) -> float:
    """Max |onnxruntime(graph) − model| over n seeded inputs: joint angles spread over (and 10 % beyond) the scaled
    range against `predict` in float64; images in [0, 1] against `encode` for an encoder. `graph`: a file or the
    serialized model."""
    import onnxruntime as ort

    session = ort.InferenceSession(graph if isinstance(graph, bytes) else str(graph),
                                   providers=["CPUExecutionProvider"])
    gen = torch.Generator().manual_seed(seed)
    if model.encodes:
        x = torch.rand(n, *model.image_shape, generator=gen)                        # (n, H, W[, C]) float32
        want = model.encode(x).double()                                             # (n, Dz) rad
    else:
        u = torch.rand(n, model.latent_dim, generator=gen, dtype=torch.float64) * 2.2 - 1.1
        x = model.body.from_unit(u)                                                  # (n, Dz) rad
        want = model.predict(x)                                                      # (n, *out) float64 reference
        x = x.to(graph_dtype(model))
    (got,) = session.run(None, {session.get_inputs()[0].name: x.numpy()})
    return float(np.abs(got.astype(np.float64) - want.numpy()).max())
