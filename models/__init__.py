"""Sensory generative models x = g(z) under one contract (see `contract.py`).

The model kinds are importable from here (`from bodyschema.models import GPRModel`), each module loaded on first
use: the GP kinds pull in gpytorch and scikit-learn, which a script using only a network model never needs.
"""

from __future__ import annotations

import importlib

from bodyschema.models.contract import BaseSensoryModel, SensoryModel, load_model, register_kind
from bodyschema.models.scaling import BodySpec

_KIND_CLASSES = {"GPRModel": "gpr", "SklearnGPRModel": "sklearn_gpr", "MDNModel": "mdn", "PixelDecoder": "pixel",
                 "MultimodalModel": "multimodal", "MultimodalMember": "multimodal", "ImageEncoder": "encoder",
                 "AnalyticModel": "analytic", "export_onnx": "onnx_export"}

__all__ = sorted(["BaseSensoryModel", "BodySpec", "SensoryModel", "load_model", "register_kind", *_KIND_CLASSES])


def __getattr__(name: str):
    if name not in _KIND_CLASSES:
        raise AttributeError(f"module 'bodyschema.models' has no attribute {name!r}")
    return getattr(importlib.import_module(f"bodyschema.models.{_KIND_CLASSES[name]}"), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
