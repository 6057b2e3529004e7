"""The model-kind registry: one table, one spelling per kind, used by the CLI, training and `load_model`.

A kind's name is the `bodyschema train <kind>` subcommand, the `kind` written in a saved model's meta.json, the
suffix of its registered name (`bodyschema-{robot}-{modality}-{kind}`) and the `kind` tag of its versions.
Names are hyphenated, as CLI words are. Models saved before the one spelling (issue 13) wrote `sklearn_gpr`
and `mm_member`: `ALIASES` maps them, in `canonical`, the one place a name read from outside is resolved.
Modules are imported lazily: a kind's module (torch, gpytorch, sklearn) is imported only when that kind is
built or loaded, and a broken module fails only the kind it holds.

A kind is its module plus its line here. What it can do (ONNX export, the GP memory guard, members, encoding) is
declared on its class (models/capabilities.py), not here. Its hyper-parameters: a `ModelConfig` class, either one
of models/configs.py (the shipped kinds: the CLI builds its help without importing any model module) or the name
of a class in the kind's own module (a new kind in one file; the CLI then imports that module to list it).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from bodyschema.models.configs import (
    EncoderConfig,
    GPRConfig,
    MDNConfig,
    ModelConfig,
    MultimodalConfig,
    PixelConfig,
    SklearnGPRConfig,
    SVGPConfig,
)


@dataclass(frozen=True)
class Kind:
    name: str                              # the one spelling (see the module doc)
    module: str                            # imported only when the kind is built or loaded
    saved: str                             # class a saved model of this kind is rebuilt as (`_from_saved`)
    trains: str | None = None              # class `bodyschema train <name>` builds; None: not trainable
    config: type[ModelConfig] | str | None = None  # its hyper-parameters: a class, or a class name in `module`
    modality: str = "ee_xyz"               # what it learns to predict unless --modality says otherwise
    summary: str = ""                      # one line of `bodyschema train --help`

    @property
    def config_class(self) -> type[ModelConfig] | None:
        """The hyper-parameter class (a name is looked up in the kind's module, imported now)."""
        return _attribute(self, self.config) if isinstance(self.config, str) else self.config


KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind("gpr", "bodyschema.models.gpr", "GPRModel", "GPRModel", GPRConfig,
         summary="Exact Gaussian process (gpytorch): closed-form Jacobian and predictive precision."),
    Kind("svgp", "bodyschema.models.svgp", "SVGPModel", "SVGPModel", SVGPConfig,
         summary="Sparse variational GP (gpytorch, inducing points): any number of poses, closed-form Jacobian."),
    Kind("sklearn-gpr", "bodyschema.models.sklearn_gpr", "SklearnGPRModel", "SklearnGPRModel", SklearnGPRConfig,
         summary="scikit-learn's Gaussian process: the baseline of gpr."),
    Kind("mdn", "bodyschema.models.mdn", "MDNModel", "MDNModel", MDNConfig,
         summary="Mixture density network: an MLP with a z-dependent precision."),
    Kind("pixel", "bodyschema.models.pixel", "PixelDecoder", "PixelDecoder", PixelConfig, modality="image",
         summary="Convolutional decoder z → camera image, with a batched VJP."),
    Kind("multimodal", "bodyschema.models.multimodal", "MultimodalMember", "MultimodalModel", MultimodalConfig,
         modality="ee_xyz,image",
         summary="One decoder per modality over a shared z, learned precisions; one registered model per modality."),
    Kind("encoder", "bodyschema.models.encoder", "ImageEncoder", "ImageEncoder", EncoderConfig, modality="image",
         summary="Image encoder: camera image → joint angles (the level-3 starting belief)."),
    Kind("analytic", "bodyschema.models.analytic", "AnalyticModel"),     # exact FK: nothing to train
)}
ALIASES = {"sklearn_gpr": "sklearn-gpr", "mm_member": "multimodal"}   # spellings of saved models before issue 13
_classes: dict[str, type] = {}         # kind → saved class of kinds declared by `register_kind` (e.g. test models)


def not_available(name: object) -> str:
    return f"Model kind {name!r} is not available. Choose one of {sorted(KINDS)}."


def canonical(name: str) -> str:
    """The registry spelling of `name` (an old spelling is mapped); an unknown name names the available ones."""
    name = ALIASES.get(name, name)
    if name not in KINDS:
        raise ValueError(not_available(name))
    return name


def get(name: str) -> Kind:
    return KINDS[canonical(name)]


def trainable() -> list[Kind]:
    """The kinds `bodyschema train` offers, in table order."""
    return [k for k in KINDS.values() if k.trains is not None and k.config is not None]


def of_config(config: ModelConfig) -> Kind:
    """The kind a hyper-parameter config trains (its class must be the kind's config class)."""
    kind = KINDS.get(getattr(config, "kind", None))
    if kind is None or kind.config_class is not type(config):
        raise ValueError(f"{type(config).__name__} is not the config of a trainable model kind. Use one of "
                         f"{[k.config_class.__name__ for k in trainable()]}.")
    return kind


def model_class(name: str) -> type:
    """The class `bodyschema train <name>` builds (imports its module now)."""
    kind = get(name)
    if kind.trains is None:
        raise ValueError(f"Model kind {kind.name!r} is not trainable. Choose one of {[k.name for k in trainable()]}.")
    return _attribute(kind, kind.trains)


def saved_class(name: str) -> type:
    """The class a saved model of kind `name` (or an old spelling of it) is rebuilt as (imports its module now)."""
    kind = get(name)
    return _classes.get(kind.name) or _attribute(kind, kind.saved)


def register(kind: Kind) -> Kind:
    """Add (or replace) a kind: a plugin's model, or a test's."""
    KINDS[kind.name] = kind
    return kind


def register_class(cls: type) -> None:
    """Called by `contract.register_kind` when a model class is defined: a shipped class must be the one the
    table names for its kind (one spelling); a class of an undeclared kind declares a loadable kind."""
    name = cls.kind
    if name in ALIASES:
        raise ValueError(f"{cls.__name__}.kind {name!r} is an old spelling: use {ALIASES[name]!r}.")
    kind = KINDS.get(name)
    if kind is None:
        register(Kind(name, cls.__module__, cls.__name__))
    elif (kind.module, kind.saved) != (cls.__module__, cls.__name__):
        raise ValueError(f"{cls.__module__}.{cls.__name__} registers kind {name!r}, which the table in "
                         f"models/kinds.py gives to {kind.module}.{kind.saved}.")
    _classes[name] = cls


def _attribute(kind: Kind, attr: str) -> type:
    try:
        module = importlib.import_module(kind.module)
    except ImportError as error:
        raise ImportError(f"Model kind {kind.name!r} could not be imported from {kind.module}: {error}") from error
    if not hasattr(module, attr):
        raise ImportError(f"Model kind {kind.name!r}: {kind.module} has no class {attr}.")
    return getattr(module, attr)
