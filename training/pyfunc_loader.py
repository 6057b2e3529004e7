"""A saved SensoryModel as an MLflow pyfunc model whose code is this installed module, not a file in the artifacts.

Logged with `mlflow.pyfunc.log_model(loader_module="bodyschema.training.pyfunc_loader", data_path=<model dir>)`:
the artifacts hold the model directory (`meta.json` + `state.pt`, tensors only) and MLflow's MLmodel file, and no
Python code. `mlflow.pyfunc.load_model("models:/<name>@champion")` imports this module from the installed
package and calls `_load_pyfunc(data_path)`, which recomputes the directory digest and compares it with the one
the tracking database records for that logged model (and its registered versions) before reading a tensor.

The MLmodel file is still read by MLflow itself before this module runs: a consumer who cannot trust the
artifact store with its MLmodel file uses `bodyschema.training.registry.load`, which reads it as data only.

pyfunc `predict(z)`: z (B, Dz) rad, float32 or float64 (numpy, list or DataFrame) → g(z) (B, *output_shape) in
the input's dtype; `params={"output": "jacobian"}` → ∂g/∂z (B, prod(output_shape), Dz) per rad; "precision" →
the diagonal Π_x (B, *output_shape). An image encoder (kind "encoder", the inverse map) predicts z (B, Dz) rad
from images (B, H, W[, C]) uint8 or float in [0, 1], and has no Jacobian output.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import mlflow
import numpy as np
import torch
from mlflow.models import ModelSignature
from mlflow.types import ParamSchema, ParamSpec

from bodyschema.errors import must_be
from bodyschema.training.digest import DIGEST_TAG, directory_sha256, logged_model_digest, verify_directory

LOADER_MODULE = __name__      # "bodyschema.training.pyfunc_loader"
OUTPUTS = ("predict", "jacobian", "precision")
_MODEL_ID = re.compile(r"^m-[0-9a-f]{32}$")


def log_sensory_model(model_dir: str | Path, model, *, name: str = "model"):
    """Log the saved model directory as a pyfunc in the active run, its digest as a tag in the tracking database.
    → (ModelInfo, directory sha256). Registration is separate (`registry.register_version`)."""
    from importlib.metadata import PackageNotFoundError, version

    digest = directory_sha256(model_dir)
    requirements = []
    for lib in ("torch", "numpy", "mlflow", "bodyschema"):
        try:
            requirements.append(f"{lib}=={version(lib)}")
        except PackageNotFoundError:
            requirements.append(lib)
    # No input schema: MLflow would refuse float32 against a float64 tensor spec; `predict` checks z itself.
    signature = ModelSignature(inputs=None, outputs=None, params=ParamSchema([ParamSpec("output", "string",
                                                                                        "predict")]))
    given = ("images (B, H, W[, C]) uint8 or float in [0, 1]" if hasattr(model, "encode")
             else f"z (B, {model.latent_dim}) rad, float32 or float64")
    metadata = {"bodyschema": {"input": given, "kind": model.kind,
                               "joint_names": list(model.body.joint_names), "modality": model.modality,
                               "output_shape": list(model.output_shape), "outputs": list(OUTPUTS)}}
    with warnings.catch_warnings():     # MLflow asks for an input example: the signature is explicit
        warnings.filterwarnings("ignore", message=".*(type hints|input example).*", category=UserWarning)
        info = mlflow.pyfunc.log_model(name=name, loader_module=LOADER_MODULE, data_path=str(model_dir),
                                       signature=signature, metadata=metadata, tags={DIGEST_TAG: digest},
                                       pip_requirements=requirements)   # explicit: MLflow would load the model
    return info, digest


def _load_pyfunc(data_path: str, model_config: dict | None = None) -> "SensoryPyfunc":
    """Called by `mlflow.pyfunc.load_model`: verify the model directory against the tracking database, load it."""
    from bodyschema.models import load_model

    data_path = Path(data_path)
    model_id = _logged_model_id(data_path)
    client = mlflow.MlflowClient()        # the tracking/registry URIs the caller resolved the model with
    verify_directory(data_path, logged_model_digest(client, model_id), f"models:/{model_id}")
    return SensoryPyfunc(load_model(data_path))


def _logged_model_id(data_path: Path) -> str:
    """The logged model id named in the MLmodel file above `data_path` (a hint to find the digest in the tracking
    database; a wrong id can only point at another model's digest, which these files will not match)."""
    from mlflow.models import Model

    for root in (data_path.parent.parent, data_path.parent):         # MLmodel sits at <root>/data/<dir>
        if (root / "MLmodel").is_file():
            model_id = Model.load(str(root / "MLmodel")).model_id
            if isinstance(model_id, str) and _MODEL_ID.match(model_id):
                return model_id
            raise ValueError(must_be("model_id in the MLmodel file", "an MLflow logged model id (m-<32 hex>)",
                                     model_id, "Load models logged by `bodyschema train` with MLflow 3."))
    raise ValueError(must_be("pyfunc data path", "inside an MLflow model directory (with an MLmodel file)",
                             str(data_path)))


class SensoryPyfunc:
    """What `mlflow.pyfunc.load_model` wraps: `predict(z, params)` → g(z), its Jacobian or its precision."""

    def __init__(self, model):
        self.model = model

    def get_raw_model(self):
        """The SensoryModel itself (`pyfunc_model.get_raw_model()`), for callers that need `vjp`."""
        return self.model

    def predict(self, model_input, params: dict | None = None) -> np.ndarray:
        output = (params or {}).get("output", "predict")
        if output not in OUTPUTS:
            raise ValueError(must_be("params['output']", f"one of {OUTPUTS}", output))
        if hasattr(self.model, "encode"):                # an image encoder: images → z (B, Dz) rad
            if output != "predict":
                raise ValueError(must_be("params['output']", "'predict' for an image encoder", output))
            images = model_input.to_numpy() if hasattr(model_input, "to_numpy") else np.asarray(model_input)
            return self.model.encode(images).numpy()
        z = _as_tensor(model_input)                                          # (B, Dz) rad
        with torch.no_grad():
            return getattr(self.model, output)(z).numpy()     # (B, *out) | (B, prod(out), Dz) | (B, *out)


def _as_tensor(model_input) -> torch.Tensor:
    """numpy / list / DataFrame of joint angles → a float32 or float64 tensor (float64 unless given float32)."""
    values = model_input.to_numpy() if hasattr(model_input, "to_numpy") else np.asarray(model_input)
    if values.dtype.kind not in "fiu":
        raise TypeError(must_be("z", "an array of joint angles in rad (float32 or float64)", str(values.dtype)))
    dtype = np.float32 if values.dtype == np.float32 else np.float64
    return torch.from_numpy(np.ascontiguousarray(values, dtype=dtype))
