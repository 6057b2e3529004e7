"""A saved SensoryModel as an MLflow pyfunc model whose code is this installed module, not a file in the artifacts.

Logged with `mlflow.pyfunc.log_model(loader_module="bodyschema.training.pyfunc_loader", data_path=<model dir>)`:
the artifacts hold the model directory (`meta.json` + `state.pt`, tensors only) and MLflow's MLmodel file, and no
Python code. `mlflow.pyfunc.load_model("models:/<name>@champion")` imports this module from the installed
package and calls `_load_pyfunc(data_path)`, which recomputes the directory digest and compares it, before reading
a tensor, with the digest the tracking database records for the model that was asked for: MLflow passes only the
downloaded path, so the URI is read from `mlflow.pyfunc.load_model`'s own frame.
- `models:/<name>@<alias>`, `models:/<name>/<version>`: the version → its logged model → the digest recorded at
  registration (`digest.version_digest`); `models:/<model id>`: that logged model's; `runs:/<run>/<name>`: the
  one logged model of that name in that run. Never an id read from the MLmodel file, which the artifact store holds.
- A path or another artifact URI (or a call not through `mlflow.pyfunc.load_model`): the version cannot be known,
  so the files need only be *some* model this tracking store recorded (as `--model <dir>`), not a particular one.

This check runs only when MLflow calls this module, which is what the MLmodel file says to do: whoever can edit it
can name other code (`loader_module:`, `code:`) and `mlflow.pyfunc.load_model` imports and runs that instead, by
MLflow's design. Use `bodyschema.load_registered` (`registry.load`) where the artifact store is not trusted: it
reads the MLmodel file as data only and never imports what it names.

pyfunc `predict(z)`: z (B, Dz) rad (numpy, list or DataFrame; the signature's Dz double columns, so MLflow hands
`predict` float64) → g(z) (B, *output_shape) float64; `params={"output": "jacobian"}` → ∂g/∂z
(B, prod(output_shape), Dz) per rad; "precision" → the diagonal Π_x (B, *output_shape). A joint angle outside the
range the model was fitted on (the body's q_low..q_high, the store's joint ranges) is refused with the house error
naming the joint and its range; `params={"extrapolate": True}` predicts there anyway. An image encoder (kind
"encoder", the inverse map) predicts z (B, Dz) rad from images (B, H, W[, C]) uint8, and has no Jacobian output.
`mlflow models serve -m models:/<name>@champion --env-manager local` serves it (POST /invocations
`{"inputs": [[z1, ..., zDz], ...]}`) from an environment with bodyschema installed (`pip_requirements`).
"""

from __future__ import annotations

import re
import sys
import warnings
from pathlib import Path

import mlflow
import numpy as np
import torch
from mlflow.models import ModelSignature
from mlflow.types import ColSpec, ParamSchema, ParamSpec, Schema, TensorSpec

from bodyschema.errors import must_be
from bodyschema.training.digest import (
    DIGEST_TAG,
    MODEL_ID,
    digest_is_recorded,
    directory_sha256,
    logged_model_digest,
    verify_directory,
    version_digest,
)
from bodyschema.training.model_card import NOTE, model_summary

LOADER_MODULE = __name__      # "bodyschema.training.pyfunc_loader"
OUTPUTS = ("predict", "jacobian", "precision")
_RUN_URI = re.compile(r"^runs:/(?P<run_id>[^/]+)/(?P<name>[^/]+?)/?$")


def log_sensory_model(model_dir: str | Path, model, *, name: str = "model"):
    """Log the saved model directory as a pyfunc in the active run, its digest as a tag in the tracking database and
    what it maps as its description (`model_card`). → (ModelInfo, directory sha256). Registration is separate
    (`champion.register_version`)."""
    digest = directory_sha256(model_dir)
    given = ("images (B, H, W[, C]) uint8" if model.encodes else f"z (B, {model.latent_dim}) rad")
    metadata = {"bodyschema": {"input": given, "kind": model.kind, "version": _installed("bodyschema"),
                               "joint_names": list(model.body.joint_names), "modality": model.modality,
                               "output_shape": list(model.output_shape), "outputs": list(OUTPUTS)}}
    with warnings.catch_warnings():     # MLflow asks for an input example: the signature is explicit
        warnings.filterwarnings("ignore", message=".*(type hints|input example).*", category=UserWarning)
        info = mlflow.pyfunc.log_model(name=name, loader_module=LOADER_MODULE, data_path=str(model_dir),
                                       signature=signature(model), metadata=metadata,
                                       tags={DIGEST_TAG: digest, NOTE: model_summary(model)},
                                       pip_requirements=pip_requirements())   # explicit: MLflow would load the model
    return info, digest


def signature(model) -> ModelSignature:
    """The pyfunc's schema. A decoder takes z as Dz double columns, one per joint in rad (MLflow upcasts float32,
    ints, lists and DataFrames to float64 before `predict`: a tensor spec would refuse all but one dtype) and gives
    `predict`'s (B, *output_shape) float64; an encoder takes (B, H, W[, C]) uint8 images and gives z (B, Dz) rad.
    `params={"output": ...}` picks the Jacobian or the precision instead (OUTPUTS); `{"extrapolate": True}` lets a
    decoder predict outside its joint ranges (a model logged before that param refuses there: MLflow drops it)."""
    params = ParamSchema([ParamSpec("output", "string", "predict"), ParamSpec("extrapolate", "boolean", False)])
    if model.encodes:
        inputs = Schema([TensorSpec(np.dtype(np.uint8), (-1, *model.input_shape))])
        return ModelSignature(inputs, Schema([TensorSpec(np.dtype(np.float32), (-1, model.latent_dim))]), params)
    inputs = Schema([ColSpec("double") for _ in range(model.latent_dim)])
    return ModelSignature(inputs, Schema([TensorSpec(np.dtype(np.float64), (-1, *model.output_shape))]), params)


def pip_requirements() -> list[str]:
    """torch, numpy and mlflow pinned at their installed public versions (a local label such as torch's `+cpu`
    is dropped: no index serves it). bodyschema itself is not listed: it is on no package index, so pip could not
    resolve it. The loader is the *installed* bodyschema (no code is stored with the model; see the module doc):
    serve with `mlflow models serve --env-manager local` from an environment that has bodyschema installed."""
    libraries = ("torch", "numpy", "mlflow")
    return [f"{lib}=={_installed(lib).split('+')[0]}" if _installed(lib) else lib for lib in libraries]


def _installed(distribution: str) -> str:
    """The installed version of `distribution`, or "" (bodyschema run from a source tree, say)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(distribution)
    except PackageNotFoundError:
        return ""


def _load_pyfunc(data_path: str, model_config: dict | None = None) -> "SensoryPyfunc":
    """Called by `mlflow.pyfunc.load_model`: verify the model directory against the tracking database's record of
    the model asked for (see the module doc), then load it."""
    from bodyschema.models import load_model

    data_path = Path(data_path)
    client = mlflow.MlflowClient()        # the tracking/registry URIs the caller resolved the model with
    uri = _requested_uri()
    recorded = _recorded_digest(client, uri) if uri is not None else None
    if recorded is None:
        _check_recorded_somewhere(client, data_path)
    else:
        verify_directory(data_path, *recorded)
    return SensoryPyfunc(load_model(data_path))


def _requested_uri() -> str | None:
    """The `model_uri` given to `mlflow.pyfunc.load_model` (MLflow 3 calls `_load_pyfunc` from it with only the
    local path), read from its frame; None when this loader was reached another way."""
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "load_model" and frame.f_globals.get("__name__") == "mlflow.pyfunc":
            uri = frame.f_locals.get("model_uri")
            return None if uri is None else str(uri)
        frame = frame.f_back
    return None


def _recorded_digest(client, uri: str) -> tuple[str, str] | None:
    """(digest, where) the tracking database records for the model `uri` names; None for a path or any other
    artifact URI, which names no model of the registry."""
    from bodyschema.training.registry import resolve_version

    if uri.startswith("models:/"):
        target = uri.removeprefix("models:/").rstrip("/")
        if MODEL_ID.match(target):
            return logged_model_digest(client, target), uri
        version = resolve_version(client, uri)        # a stage or other form: the house error naming the two forms
        return version_digest(client, version), f"models:/{version.name}/{version.version}"
    run = _RUN_URI.match(uri)
    if run is None:
        return None
    digests = {logged_model_digest(client, m.model_id) for m in _logged_models_of_run(client, *run.groups())}
    if len(digests) != 1:
        raise ValueError(must_be(f"the logged models named {run['name']!r} in run {run['run_id']}",
                                 "one model (one recorded digest)", f"{len(digests)} digests",
                                 "Load it as models:/<name>@<alias> or models:/<model id> instead."))
    return digests.pop(), uri


def _logged_models_of_run(client, run_id: str, name: str) -> list:
    from mlflow.exceptions import MlflowException

    try:
        experiment_id = client.get_run(run_id).info.experiment_id
    except MlflowException:
        return []
    return [m for m in client.search_logged_models([experiment_id], filter_string=f"name = '{name}'")
            if m.source_run_id == run_id]


def _check_recorded_somewhere(client, data_path: Path) -> None:
    """A model directory reached by path: its digest must be one the tracking database records (any model)."""
    digest = directory_sha256(data_path)
    if digest_is_recorded(client, digest) is None:
        raise ValueError(must_be(f"model directory {str(data_path)!r}", "a model logged by `bodyschema train` in "
                                 f"{client.tracking_uri} (its sha256 recorded there)",
                                 f"sha256 {digest[:16]}… recorded nowhere", "Load it by its registry URI "
                                 "(models:/<name>@champion), or set MLFLOW_TRACKING_URI to the store it was logged "
                                 "in."))


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
        if self.model.encodes:                           # an image encoder: images → z (B, Dz) rad
            if output != "predict":
                raise ValueError(must_be("params['output']", "'predict' for an image encoder", output))
            images = model_input.to_numpy() if hasattr(model_input, "to_numpy") else np.asarray(model_input)
            return self.model.encode(images).numpy()
        z = _as_tensor(model_input)                                          # (B, Dz) rad
        if not (params or {}).get("extrapolate", False):
            check_within_range(self.model.body, z)
        with torch.no_grad():
            return getattr(self.model, output)(z).numpy()     # (B, *out) | (B, prod(out), Dz) | (B, *out)


def _as_tensor(model_input) -> torch.Tensor:
    """numpy / list / DataFrame of joint angles → a float32 or float64 tensor (float64 unless given float32)."""
    values = model_input.to_numpy() if hasattr(model_input, "to_numpy") else np.asarray(model_input)
    if values.dtype.kind not in "fiu":
        raise TypeError(must_be("z", "an array of joint angles in rad (float32 or float64)", str(values.dtype)))
    dtype = np.float32 if values.dtype == np.float32 else np.float64
    return torch.from_numpy(np.array(values, dtype=dtype))      # a copy: a DataFrame's array may be read-only


RANGE_TOLERANCE_RAD = 1e-6     # a pose read back at its joint's limit (float32 rounding) is inside


def check_within_range(body, z: torch.Tensor) -> None:
    """The house error for the first joint whose angle in `z` (B, Dz) rad lies outside the range the model was
    fitted on (`body.q_low`..`body.q_high`): a model there extrapolates silently (a GP falls back to its mean, a
    network to anything), so it is refused unless the caller asks (`extrapolate`). NaN counts as outside."""
    if z.ndim != 2 or z.shape[1] != len(body.joint_names):
        raise ValueError(must_be("z", f"of shape (B, {len(body.joint_names)}): one column per joint "
                                      f"{list(body.joint_names)}, in rad", tuple(z.shape)))
    low = torch.tensor(body.q_low, dtype=z.dtype) - RANGE_TOLERANCE_RAD      # (Dz,)
    high = torch.tensor(body.q_high, dtype=z.dtype) + RANGE_TOLERANCE_RAD
    inside = (z >= low) & (z <= high)                                       # (B, Dz)
    if bool(inside.all()):
        return
    row, col = (int(i) for i in (~inside).nonzero()[0])
    name = body.joint_names[col]
    raise ValueError(must_be(f"z[{row}, {col}] (joint {name})",
                             f"within its range [{body.q_low[col]:.4g}, {body.q_high[col]:.4g}] rad (the range the "
                             "model was fitted on)", f"{float(z[row, col]):.4g} rad",
                             'Pass params={"extrapolate": true} to predict outside it anyway (an extrapolation).'))
