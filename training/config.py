"""`TrainConfig`: one training run (model kind, dataset, hyper-parameters, tracking), and the model-kind table.

The fields that change the trained model (kind, modality, data, seed, split, hyper-parameters) form the
run's identity (`identity()`); its hash keys the run directory, so a killed run started again with the same
config resumes from its checkpoint. The fields that only change *where* results go or how they are shown
(tracking URI, experiment, run root, progress, register, device) are left out of the hash.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import inspect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bodyschema.errors import must_be

# kind -> (module, class). Modules are imported lazily: a kind whose module is broken only fails when chosen.
MODEL_KINDS: dict[str, tuple[str, str]] = {
    "gpr": ("bodyschema.models.gpr", "GPRModel"),
    "sklearn-gpr": ("bodyschema.models.sklearn_gpr", "SklearnGPRModel"),
    "mdn": ("bodyschema.models.mdn", "MDNModel"),
    "pixel": ("bodyschema.models.pixel", "PixelDecoder"),
    "multimodal": ("bodyschema.models.multimodal", "MultimodalModel"),
    "encoder": ("bodyschema.models.encoder", "ImageEncoder"),   # the inverse: image → joint angles
}
DEFAULT_MODALITY = {"pixel": "image", "multimodal": "ee_xyz,image", "encoder": "image"}   # else "ee_xyz"
MODALITIES = ("ee_xyz", "ee_pixel", "image", "touch", "jacobian", "joints")
NON_IDENTITY_FIELDS = ("tracking_uri", "experiment", "run_root", "progress", "register", "device")


def kind_not_available(kind: object) -> str:
    return f"Model kind {kind!r} is not available. Choose one of {sorted(MODEL_KINDS)}."


@dataclass(frozen=True)
class TrainConfig:
    """Train one sensory model g(z) on one dataset, log it to MLflow and register it."""

    model: str  # model kind: gpr | sklearn-gpr | mdn | pixel | multimodal | encoder (image → joint angles)
    data: Path  # the Zarr store written by `bodyschema datagen`
    modality: str | None = None  # what g predicts; None: "image" (pixel), "ee_xyz,image" (multimodal), else "ee_xyz"
    seed: int = 0  # split and model init; same seed and data -> same model
    val_fraction: float = 0.2  # held-out share (whole episodes when the store has `episode`)
    max_train: int | None = None  # cap on training samples (GPs are O(N^3)); None: all of them
    hyper: dict[str, str] = field(default_factory=dict)  # model hyper-parameters: --hyper epochs 50 hidden [64,64]
    experiment: str = "bodyschema"  # MLflow experiment; one for the whole project keeps runs comparable
    tracking_uri: str | None = None  # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db (no server)
    run_root: Path = Path("runs")  # checkpoints, saved model and plots, in <run_root>/<kind>-<modality>-<hash>
    register: bool = True  # register the model and maybe move the `champion` alias; False: log the run only
    progress: bool = True  # progress bars (off in tests and batch jobs)
    device: str = "cpu"  # cpu | cuda | cuda:N: where the network kinds (pixel, encoder) train; saved on CPU either way

    def __post_init__(self) -> None:
        def fix(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        problems: list[str] = []
        if self.model not in MODEL_KINDS:
            problems.append(kind_not_available(self.model))
        fix("data", Path(self.data))
        fix("run_root", Path(self.run_root))
        if self.modality is None:
            fix("modality", DEFAULT_MODALITY.get(self.model, "ee_xyz"))
        elif not isinstance(self.modality, str) or not all(self.modality.split(",")):
            problems.append(must_be("modality", f"a dataset array name such as {MODALITIES}", self.modality))
        elif "," in self.modality and self.model != "multimodal":
            problems.append(must_be("modality", f"one array name for model kind {self.model!r}", self.modality,
                                    "Several modalities (comma-separated) need --model multimodal."))
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            problems.append(must_be("seed", "an integer >= 0", self.seed))
        if not (isinstance(self.val_fraction, (int, float)) and 0 < self.val_fraction < 1):
            problems.append(must_be("val_fraction", "a number in (0, 1)", self.val_fraction,
                                    "The champion is chosen on held-out data, so some must be held out."))
        if self.max_train is not None and (not isinstance(self.max_train, int) or self.max_train < 1):
            problems.append(must_be("max_train", "a positive integer or None", self.max_train))
        if not isinstance(self.hyper, dict) or not all(isinstance(k, str) for k in self.hyper):
            problems.append(must_be("hyper", "a dict of name -> value", self.hyper))
        if not isinstance(self.experiment, str) or not self.experiment:
            problems.append(must_be("experiment", "a non-empty name", self.experiment))
        try:
            from bodyschema.models.device import check_device   # imports torch: only when a config is built

            check_device(self.device)
        except ValueError as error:
            problems.append(str(error))
        if problems:
            raise ValueError("\n".join(problems))

    @property
    def modalities(self) -> tuple[str, ...]:
        return tuple(m.strip() for m in self.modality.split(","))

    def hyper_values(self) -> dict[str, Any]:
        """`hyper` with values parsed: JSON literals ("50", "1e-3", "true", "[64, 64]") become numbers etc."""
        return {k: _parse_value(v) for k, v in sorted(self.hyper.items())}

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (Path as str), as logged to MLflow params and the run directory."""
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))

    def identity(self, dataset_sha256: str) -> dict[str, Any]:
        """What determines the trained model: the identity fields and the data's content digest (not its path:
        a moved or copied store with the same content is the same data)."""
        values = {k: v for k, v in self.to_dict().items() if k not in (*NON_IDENTITY_FIELDS, "data")}
        values["hyper"] = self.hyper_values()
        values["dataset_sha256"] = dataset_sha256
        return values

    def config_hash(self, dataset_sha256: str) -> str:
        """sha256 of `identity()`: the run directory key (a resumed run must train the very same thing)."""
        blob = json.dumps(self.identity(dataset_sha256), sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()

    def run_dir(self, dataset_sha256: str) -> Path:
        return self.run_root / f"{self.model}-{'+'.join(self.modalities)}-{self.config_hash(dataset_sha256)[:12]}"


def _parse_value(value: Any) -> Any:
    if not isinstance(value, str):
        return value
    try:
        parsed = json.loads(value)
    except json.JSONDecodeError:
        return value                     # a bare word such as "rbf" stays a string
    if isinstance(parsed, float) and not math.isfinite(parsed):
        return value
    return tuple(parsed) if isinstance(parsed, list) else parsed


def model_class(kind: str) -> type:
    """The model class of a kind; an unknown kind names the available ones."""
    if kind not in MODEL_KINDS:
        raise ValueError(kind_not_available(kind))
    module_name, class_name = MODEL_KINDS[kind]
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ImportError(f"Model kind {kind!r} could not be imported from {module_name}: {error}") from error
    if not hasattr(module, class_name):
        raise ImportError(f"Model kind {kind!r}: {module_name} has no class {class_name}.")
    return getattr(module, class_name)


def build_model(kind: str, body, output_shapes: dict[str, tuple[int, ...]], hyper: dict[str, Any]):
    """`Model(body, modality, output_shape, **hyper)`, or for multimodal `Model(body, output_shapes, **hyper)`.

    A wrong hyper-parameter name is reported with the accepted ones.
    """
    cls = model_class(kind)
    params = inspect.signature(cls).parameters
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        accepted = [p for p in params
                    if p not in ("self", "body", "modality", "output_shape", "output_shapes", "image_shape")]
        unknown = sorted(set(hyper) - set(accepted))
        if unknown:
            raise ValueError(must_be("hyper", f"names accepted by {cls.__name__}: {accepted}", unknown))
    if "output_shapes" in params:
        return cls(body, {m: tuple(s) for m, s in output_shapes.items()}, **hyper)
    if len(output_shapes) != 1:
        raise ValueError(must_be("modality", f"a single modality for model kind {kind!r}", sorted(output_shapes)))
    ((modality, shape),) = output_shapes.items()
    return cls(body, modality, tuple(shape), **hyper)
