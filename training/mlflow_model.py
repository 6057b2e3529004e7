"""A saved SensoryModel as an MLflow pyfunc model, logged as code (no pickle) with a content digest.

The pyfunc is logged "from code" (MLflow 3's recommended form): MLflow stores this file and the model
directory (`meta.json` + `state.pt`, tensors only) as artifacts, never a cloudpickled object, so loading it
runs no serialized code. `directory_sha256` of the model directory is recorded at logging time (as a run tag,
a model-version tag and in the pyfunc's `model_config`) and checked before the tensors are read.

pyfunc `predict`: z (B, Dz) rad, float64 array → g(z) (B, *output_shape). AIF code does not go through the
pyfunc (it needs `jacobian`, `vjp`, `precision`): `bodyschema.training.registry.load` returns the model itself.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import mlflow
import numpy as np
import torch
from mlflow.pyfunc import PythonModel

ARTIFACT_KEY = "sensory_model"        # the model directory inside the logged MLflow model: artifacts/<key>
DIGEST_TAG = "bodyschema.model_sha256"


def directory_sha256(path: str | Path) -> str:
    """sha256 over the sorted relative paths and bytes of every file under `path` (the saved model)."""
    path = Path(path)
    digest = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file())
    if not files:
        raise FileNotFoundError(f"Model directory {str(path)!r} holds no files; nothing to digest.")
    for file in files:
        digest.update(file.relative_to(path).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(file.read_bytes()).digest())
    return digest.hexdigest()


def verify_directory(path: str | Path, expected: str | None, where: str) -> None:
    """Raise unless the model directory's digest equals `expected` (recorded when it was logged)."""
    if not expected:
        raise ValueError(f"{where} has no recorded {DIGEST_TAG}, so its artifacts cannot be checked. "
                         "Only models logged by `bodyschema train` can be loaded.")
    actual = directory_sha256(path)
    if actual != expected:
        raise ValueError(f"Model artifacts of {where} must have sha256 {expected}. Got {actual}. "
                         "The files changed after logging (tampering or a partial copy); refusing to load them.")


class SensoryModelPyfunc(PythonModel):
    """pyfunc wrapper: `load_context` checks the digest and calls `load_model`; `predict` returns g(z)."""

    def load_context(self, context) -> None:
        from bodyschema.models import load_model

        model_dir = context.artifacts[ARTIFACT_KEY]
        verify_directory(model_dir, (context.model_config or {}).get("model_sha256"), "this pyfunc model")
        self.model = load_model(model_dir)

    def predict(self, context, model_input: np.ndarray, params=None) -> np.ndarray:   # ndarray: no type validation
        z = torch.as_tensor(np.asarray(model_input, dtype=np.float64))      # (B, Dz) rad
        with torch.no_grad():
            return self.model.predict(z).numpy()                           # (B, *output_shape)


def log_sensory_model(model_dir: str | Path, model, *, registered_name: str | None = None,
                      name: str = "model"):
    """Log the saved model directory as a pyfunc (from code) in the active run. → (ModelInfo, directory sha256)"""
    from importlib.metadata import PackageNotFoundError, version

    digest = directory_sha256(model_dir)
    z = np.zeros((2, model.latent_dim), dtype=np.float64)                      # (2, Dz) rad, an input example
    x = np.zeros((2, *model.output_shape), dtype=np.float64)                   # (2, *out)
    requirements = []
    for lib in ("torch", "numpy", "mlflow", "bodyschema"):
        try:
            requirements.append(f"{lib}=={version(lib)}")
        except PackageNotFoundError:
            requirements.append(lib)
    with warnings.catch_warnings():     # MLflow asks for an input example: the signature is explicit
        warnings.filterwarnings("ignore", message=".*(type hints|input example).*", category=UserWarning)
        info = mlflow.pyfunc.log_model(
            name=name, python_model=Path(__file__), artifacts={ARTIFACT_KEY: str(model_dir)},
            model_config={"model_sha256": digest}, signature=mlflow.models.infer_signature(z, x),
            pip_requirements=requirements,          # explicit: MLflow would otherwise load the model to infer them
            registered_model_name=registered_name, await_registration_for=60)
    return info, digest


if not __name__.startswith("bodyschema."):
    # Executed by MLflow as the model's code file (models from code), not imported as part of the package.
    mlflow.models.set_model(SensoryModelPyfunc())
