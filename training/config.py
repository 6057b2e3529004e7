"""`TrainConfig`: one training run (a model kind with its typed hyper-parameters, the dataset, tracking).

`TrainConfig[M]` is generic over the kind's hyper-parameter config (models/configs.py): `bodyschema train <kind>`
is one subcommand per kind (`train_commands`), whose flags are the shared fields below plus that kind's
hyper-parameters (`--epochs`, `--noise-floor`, …), each with its default in `--help`. In Python:
`TrainConfig(model=MDNConfig(epochs=60), data=store)`; the config's class names the kind.

The fields that change the trained model (kind, modality, data, seed, split, hyper-parameters) form the
run's identity (`identity()`); its hash keys the run directory, so a killed run started again with the same
config resumes from its checkpoint. Every hyper-parameter is in it with its value (defaults included), so a
default that changes in the code starts a new run rather than resuming a different model. The fields that only
change *where* results go or how they are shown (tracking URI, experiment, run root, progress, register,
device) are left out of the hash.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Generic, TypeVar

from bodyschema.base.modalities import MODALITIES
from bodyschema.cli_marks import Flat
from bodyschema.errors import must_be
from bodyschema.log import Progress
from bodyschema.models import kinds
from bodyschema.models.configs import ModelConfig

NON_IDENTITY_FIELDS = ("tracking_uri", "experiment", "run_root", "progress", "register", "device")
M = TypeVar("M", bound=ModelConfig)


@dataclass(frozen=True)
class TrainConfig(Generic[M]):
    """Train one sensory model g(z) on one dataset, log it to MLflow and register it."""

    data: Path  # the Zarr store written by `bodyschema datagen`
    # the model kind's hyper-parameters (its constructor's keywords, with its defaults)
    model: Annotated[M, Flat()]
    modality: str | None = None  # what g predicts; None: image (pixel, encoder), ee_xyz,image (multimodal), else ee_xyz
    seed: int = 0  # split and model init; same seed and data -> same model
    val_fraction: float = 0.2  # held-out share (whole episodes when the store has `episode`)
    max_train: int | None = None  # cap on training samples (GPs are O(N^3)); None: all of them
    experiment: str = "bodyschema"  # MLflow experiment; one for the whole project keeps runs comparable
    tracking_uri: str | None = None  # None: $MLFLOW_TRACKING_URI, else sqlite:///<cwd>/mlflow.db (no server)
    run_root: Path = Path("runs")  # checkpoints, saved model and plots, in <run_root>/<kind>-<modality>-<hash>
    register: bool = True  # register the model and maybe move the `champion` alias; False: log the run only
    progress: Progress = False  # show progress bars (--quiet hides them too)
    device: str = "cpu"  # cpu | cuda | cuda:N: where the network kinds (pixel, encoder) train; saved on CPU either way
    mixed_precision: bool = False  # bf16 autocast of the network kinds' forward pass (models/_nn_device.py)

    def __post_init__(self) -> None:
        def fix(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        problems: list[str] = []
        try:
            kind = kinds.of_config(self.model)
        except ValueError as error:
            problems.append(str(error))
            kind = None
        fix("data", Path(self.data))
        fix("run_root", Path(self.run_root))
        if self.modality is None:
            fix("modality", kind.modality if kind else "ee_xyz")
        elif not isinstance(self.modality, str) or not all(self.modality.split(",")):
            problems.append(must_be("modality", f"a dataset array name such as {list(MODALITIES)}", self.modality))
        elif "," in self.modality and kind is not None and not kinds.model_class(kind.name).has_members:
            problems.append(must_be("modality", f"one array name for model kind {kind.name!r}", self.modality,
                                    "Several modalities (comma-separated) need `bodyschema train multimodal`."))
        elif len(set(self.modalities)) != len(self.modalities):
            problems.append(must_be("modality", "distinct array names", self.modality,
                                    "Name each modality once (one decoder is trained per modality)."))
        problems += self._split_problems()
        if not isinstance(self.experiment, str) or not self.experiment:
            problems.append(must_be("experiment", "a non-empty name", self.experiment))
        try:
            from bodyschema.models.device import check_device  # imports torch: only when a config is built

            check_device(self.device)
        except ValueError as error:
            problems.append(str(error))
        if problems:
            raise ValueError("\n".join(problems))

    def _split_problems(self) -> list[str]:
        problems = []
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            problems.append(must_be("seed", "an integer >= 0", self.seed))
        if not (isinstance(self.val_fraction, (int, float)) and 0 < self.val_fraction < 1):
            problems.append(must_be("val_fraction", "a number in (0, 1)", self.val_fraction,
                                    "The champion is chosen on held-out data, so some must be held out."))
        if self.max_train is not None and (not isinstance(self.max_train, int) or self.max_train < 1):
            problems.append(must_be("max_train", "a positive integer or None", self.max_train))
        return problems

    @property
    def kind(self) -> str:
        """The model kind's name (models/kinds.py), e.g. "gpr"."""
        return self.model.kind

    @property
    def modalities(self) -> tuple[str, ...]:
        return tuple(m.strip() for m in self.modality.split(","))

    def hyper_values(self) -> dict[str, Any]:
        """Every hyper-parameter of the kind with its value (defaults included), as plain JSON values."""
        return json.loads(json.dumps(self.model.to_kwargs(), sort_keys=True))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON values (Path as str), as logged to MLflow params and the run directory."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "model"}
        return json.loads(json.dumps({**values, "model": self.kind, "hyper": self.hyper_values()}, default=str))

    def identity(self, dataset_sha256: str) -> dict[str, Any]:
        """What determines the trained model: the kind, the identity fields, every hyper-parameter and the data's
        content digest (not its path: a moved or copied store with the same content is the same data)."""
        values = {k: v for k, v in self.to_dict().items() if k not in (*NON_IDENTITY_FIELDS, "data")}
        values["dataset_sha256"] = dataset_sha256
        return values

    def config_hash(self, dataset_sha256: str) -> str:
        """sha256 of `identity()`: the run directory key (a resumed run must train the very same thing)."""
        blob = json.dumps(self.identity(dataset_sha256), sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()

    def run_dir(self, dataset_sha256: str) -> Path:
        return self.run_root / f"{self.kind}-{'+'.join(self.modalities)}-{self.config_hash(dataset_sha256)[:12]}"


def train_commands() -> list[tuple[str, type, str]]:
    """(subcommand, config type, description) of every trainable kind: `bodyschema train <kind>`."""
    return [(k.name, TrainConfig[k.config_class], k.summary) for k in kinds.trainable()]


def untrained_model(config: TrainConfig, body, output_shapes: dict[str, tuple[int, ...]]):
    """The untrained model of `config`: `Model(body, modality, output_shape, **hyper)`, or for a kind that trains
    several modalities at once (`has_members`: multimodal) `Model(body, output_shapes, **hyper)`."""
    cls = kinds.model_class(config.kind)
    hyper = config.model.to_kwargs()
    if cls.has_members:
        return cls(body, {m: tuple(s) for m, s in output_shapes.items()}, **hyper)
    if len(output_shapes) != 1:
        raise ValueError(must_be("modality", f"a single modality for model kind {config.kind!r}",
                                 sorted(output_shapes)))
    ((modality, shape),) = output_shapes.items()
    return cls(body, modality, tuple(shape), **hyper)
