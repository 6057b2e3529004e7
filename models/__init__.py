"""Sensory generative models x = g(z) under one contract (see `contract.py`).

The model kinds are importable from here (`from bodyschema.models import GPRModel`), each module loaded on first
use: the GP kinds pull in gpytorch and scikit-learn, which a script using only a network model never needs.
"""

from __future__ import annotations

from bodyschema.lazy import lazy_exports

# Every name is lazy, the contract's too: `bodyschema.models.configs` and `kinds` (the CLI's `train` flags) must
# import without torch, and importing them runs this file first.
_KIND_CLASSES = {"GPRModel": "gpr", "SVGPModel": "svgp", "SklearnGPRModel": "sklearn_gpr", "MDNModel": "mdn",
                 "PixelDecoder": "pixel",
                 "MultimodalModel": "multimodal", "MultimodalMember": "multimodal", "ImageEncoder": "encoder",
                 "AnalyticModel": "analytic", "export_onnx": "onnx_export", "BaseSensoryModel": "contract",
                 "SensoryModel": "contract", "load_model": "contract", "register_kind": "contract",
                 "BodySpec": "scaling"}

__all__, __getattr__, __dir__ = lazy_exports(
    "bodyschema.models", globals(),
    {name: (f"bodyschema.models.{module}", name) for name, module in _KIND_CLASSES.items()})
