"""Sensory generative models x = g(z) under one contract (see `contract.py`).

The model kinds are importable from here (`from bodyschema.models import GPRModel`), each module loaded on first
use: the GP kinds pull in gpytorch and scikit-learn, which a script using only a network model never needs.
"""

from __future__ import annotations

import importlib

# Every name is lazy, the contract's too: `bodyschema.models.configs` and `kinds` (the CLI's `train` flags) must
# import without torch, and importing them runs this file first.
_KIND_CLASSES = {"GPRModel": "gpr", "SklearnGPRModel": "sklearn_gpr", "MDNModel": "mdn", "PixelDecoder": "pixel",
                 "MultimodalModel": "multimodal", "MultimodalMember": "multimodal", "ImageEncoder": "encoder",
                 "AnalyticModel": "analytic", "export_onnx": "onnx_export", "BaseSensoryModel": "contract",
                 "SensoryModel": "contract", "load_model": "contract", "register_kind": "contract",
                 "BodySpec": "scaling"}

__all__ = sorted(_KIND_CLASSES)


def __getattr__(name: str):
    if name not in _KIND_CLASSES:
        raise AttributeError(f"module 'bodyschema.models' has no attribute {name!r}")
    return getattr(importlib.import_module(f"bodyschema.models.{_KIND_CLASSES[name]}"), name)


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
