"""The SensoryModel contract: x = g(z) with its Jacobian, VJP and precision, batched over trials.

Every model (analytic FK, GPR, MDN, pixel decoder, multimodal member) subclasses `BaseSensoryModel`, which
validates inputs at the edge, keeps the output dtype equal to the input dtype, and saves/loads the model
as `meta.json` (kind, body, config, the sha256 of state.pt) + `state.pt` (tensors only, loaded with
`weights_only=True`: no code runs when a saved model is read). Subclasses implement the underscore hooks only.
Through `Estimator` (shared with the image encoder and the multimodal trainer) every kind follows scikit-learn's
estimator conventions: `get_params`/`set_params`, so `sklearn.base.clone` works, a short repr, and
`NotFittedError` (scikit-learn's subclass) before `fit`.

The sha256 in meta.json is an integrity check against corruption (a flipped byte, a partial copy, a state.pt of
another save), not authenticity: whoever can edit state.pt can edit meta.json too. Authenticity is the tracking
database's digest, checked by `bodyschema.training.registry.load` (see training/digest.py).
"""

from __future__ import annotations

import hashlib
import json
import pickle
from pathlib import Path
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np
import torch

from bodyschema.errors import must_be
from bodyschema.models import kinds
from bodyschema.models.capabilities import Capabilities
from bodyschema.models.estimator import Estimator
from bodyschema.models.files import torch_bytes, write_atomically
from bodyschema.models.scaling import BodySpec

FLOAT_DTYPES = (torch.float32, torch.float64)
FORMAT_VERSION = 1
STATE_SHA256 = "state_sha256"   # meta.json key; models saved before it have none and load unchecked
# optional calls a model may add to the contract, prediction and derivative from one forward pass (networks):
# predict_and_jacobian(z) → (g, J) and predict_and_vjp(z) → (g, v ↦ Jᵀv); free energy uses them where present,
# so a wrapper of a model (sensor noise, timing) must pass them on
FUSED_CALLS = ("predict_and_jacobian", "predict_and_vjp")


@runtime_checkable
class SensoryModel(Protocol):
    latent_dim: int                  # Dz: number of joints, z in rad
    modality: str                    # "ee_xyz" | "ee_pixel" | "joints" | "image" | "touch" | ...
    output_shape: tuple[int, ...]    # per-sample shape of x
    body: BodySpec                   # robot, joint names and the latent scaling

    def predict(self, z: torch.Tensor) -> torch.Tensor: ...             # (B, Dz) → (B, *out)
    def jacobian(self, z: torch.Tensor) -> torch.Tensor: ...            # (B, Dz) → (B, prod(out), Dz)
    def vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor: ...  # (B, Dz), (B, *out) → (B, Dz)
    def precision(self, z: torch.Tensor) -> torch.Tensor: ...           # (B, Dz) → (B, *out), Π_x diagonal
    def save(self, path: str | Path) -> None: ...


def register_kind(cls):
    """Class decorator: make a model kind loadable by `load_model` from its saved `meta.json`. A shipped kind is
    declared in models/kinds.py (the one registry), which this checks; another kind is declared here."""
    kinds.register_class(cls)
    return cls


class BaseSensoryModel(Estimator, Capabilities):
    sweepable = True       # one decoder, scored by its val_rmse (models/capabilities.py)
    # True when Π depends on z (GPR predictive variance, MDN mixture): F = ½εᵀΠ(z)ε − ½ln|Π(z)| then needs ∂Π/∂z
    precision_varies: ClassVar[bool] = False

    @property
    def sensor_precision(self) -> float | None:
        """Π of the sensor that reads this modality (base/modalities.py: 1/σ², σ = 1 mm, 1 px, 1°), or None (an
        image, a modality outside the table): what perception uses instead of a Π that varies with the pose
        (aif/precisions.py)."""
        from bodyschema.base import modalities
        row = modalities.find(self.modality)
        return None if row is None else row.precision

    @property
    def fitted_choices(self) -> str:
        """What the fit chose that the hyper-parameters do not say (e.g. `gpr`'s kernel under "auto"), one sentence
        for the model card and the registry's description; "" where nothing was chosen."""
        return ""

    def __init__(self, body: BodySpec, modality: str, output_shape: tuple[int, ...]):
        self.body = check_body(body)
        self.latent_dim = body.latent_dim
        self.modality = modality
        self.output_shape = tuple(int(s) for s in output_shape)

    # ---- public API: validate at the edge, then call the hooks --------------------------------------
    def predict(self, z: torch.Tensor) -> torch.Tensor:
        z = self._check_z(z)
        return self._predict(z).to(z.dtype)

    def jacobian(self, z: torch.Tensor) -> torch.Tensor:
        z = self._check_z(z)
        return self._jacobian(z).to(z.dtype)

    def vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        z = self._check_z(z)
        v = self._check_v(v, z)
        return self._vjp(z, v).to(z.dtype)

    def precision(self, z: torch.Tensor) -> torch.Tensor:
        z = self._check_z(z)
        return self._precision(z).to(z.dtype)

    def precision_vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """(∂Π/∂z)ᵀ v for the diagonal precision: (B, Dz), (B, *out) → (B, Dz); zero when Π is constant."""
        z = self._check_z(z)
        v = self._check_v(v, z)
        if not self.precision_varies:
            return torch.zeros_like(z)
        return self._precision_vjp(z, v).to(z.dtype)

    # ---- hooks --------------------------------------------------------------------------------------
    def _predict(self, z: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _jacobian(self, z: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        # Jᵀv; models with large outputs (images) override this to avoid building J.
        jac = self._jacobian(z).to(z.dtype)                              # (B, O, Dz)
        return torch.einsum("bod,bo->bd", jac, v.reshape(v.shape[0], -1))

    def _precision(self, z: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _precision_vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        # By autograd through `_precision` (torch models); a model computed outside torch overrides this.
        with torch.enable_grad():
            zg = z.detach().requires_grad_(True)
            pi = self._precision(zg)                                       # (B, *out)
            (grad,) = torch.autograd.grad(pi, zg, v.to(pi.dtype))
        return grad                                                        # (B, Dz)

    def _config(self) -> dict:
        """JSON-serializable hyper-parameters needed to rebuild the model."""
        return {}

    def _state(self) -> dict[str, torch.Tensor]:
        """Learned tensors."""
        return {}

    @classmethod
    def _from_saved(cls, body: BodySpec, modality: str, output_shape: tuple[int, ...], config: dict,
                    state: dict[str, torch.Tensor]) -> "BaseSensoryModel":
        raise NotImplementedError

    # ---- persistence --------------------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        """Write `path/meta.json` and `path/state.pt` (a directory, created if missing), both or neither."""
        self._require_fitted()
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        state = torch_bytes({k: v.detach().cpu() for k, v in self._state().items()})
        meta = {"format_version": FORMAT_VERSION, "kind": self.kind, "modality": self.modality,
                "output_shape": list(self.output_shape), "body": self.body.to_dict(), "config": self._config(),
                STATE_SHA256: hashlib.sha256(state).hexdigest()}
        write_atomically({path / "state.pt": state, path / "meta.json": json.dumps(meta, indent=2).encode()})

    @classmethod
    def load(cls, path: str | Path) -> "BaseSensoryModel":
        return load_model(path)

    # ---- validation ---------------------------------------------------------------------------------
    def _check_z(self, z) -> torch.Tensor:
        self._require_fitted()
        z = as_input(z)
        if not isinstance(z, torch.Tensor):
            raise TypeError(must_be("z", "a torch.Tensor or numpy array of joint angles in rad", type(z).__name__,
                                    "Convert with torch.as_tensor(z, dtype=torch.float64)."))
        if z.dtype not in FLOAT_DTYPES:
            raise TypeError(must_be("z.dtype", "torch.float32 or torch.float64", z.dtype))
        if z.ndim != 2 or z.shape[1] != self.latent_dim:
            raise ValueError(must_be("z", f"of shape (B, {self.latent_dim}) for joints {list(self.body.joint_names)}",
                                     tuple(z.shape), "Add a batch axis with z[None] for a single pose."))
        if not torch.isfinite(z).all():
            raise ValueError(must_be("z", "finite", "NaN or inf values", "Check the belief or the observation."))
        return z

    def _check_v(self, v, z: torch.Tensor) -> torch.Tensor:
        v = as_input(v)
        if not isinstance(v, torch.Tensor) or tuple(v.shape) != (z.shape[0], *self.output_shape):
            got = tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
            raise ValueError(must_be("v", f"a tensor of shape ({z.shape[0]}, {', '.join(map(str, self.output_shape))})",
                                     got))
        return v.to(z.dtype)


def check_body(body) -> BodySpec:
    """The house error for a constructor given something else than a BodySpec (e.g. by set_params)."""
    if not isinstance(body, BodySpec):
        raise TypeError(must_be("body", "a BodySpec (robot, joint names and ranges)", type(body).__name__,
                                "Take it from a dataset (`load_dataset(...).body`) or a model (`model.body`)."))
    return body


def as_input(a):
    """A numpy array at the public edge becomes a tensor (sharing its memory); outputs are tensors either way."""
    return torch.from_numpy(a) if isinstance(a, np.ndarray) else a


def load_model(path: str | Path) -> BaseSensoryModel:
    """Load any saved model kind from a directory written by `save` (a SensoryModel, or an image encoder)."""
    path = Path(path)
    meta_file = path / "meta.json"
    if not meta_file.is_file():
        raise FileNotFoundError(must_be("path", "a directory holding meta.json and state.pt", str(path),
                                        "Pass the directory given to model.save()."))
    meta = json.loads(meta_file.read_text())
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(must_be("format_version", str(FORMAT_VERSION), meta.get("format_version")))
    try:
        cls = kinds.saved_class(meta["kind"])      # imports only that kind's module; old spellings are aliases
    except ValueError:
        raise ValueError(must_be("model kind", f"one of {sorted(kinds.KINDS)}", meta["kind"])) from None
    _check_state_sha256(path / "state.pt", meta.get(STATE_SHA256))
    try:
        state = torch.load(path / "state.pt", weights_only=True)
    except pickle.UnpicklingError:
        # torch's own message advises weights_only=False, i.e. running the file's code: never do that here.
        raise ValueError(must_be(f"{path / 'state.pt'}", "tensors only (as written by model.save)",
                                 "a pickle that needs code to load", "Refusing to run it: re-save the model with "
                                 "`bodyschema train` or model.save().")) from None
    except (RuntimeError, EOFError) as error:      # truncated or not a torch file at all
        raise ValueError(must_be(f"{path / 'state.pt'}", "a complete torch file written by model.save",
                                 str(error).splitlines()[0] if str(error) else type(error).__name__,
                                 "The file is damaged or partial: copy or train the model again.")) from None
    return cls._from_saved(BodySpec.from_dict(meta["body"]), meta["modality"], tuple(meta["output_shape"]),
                           meta["config"], state)


def _check_state_sha256(state_file: Path, recorded: str | None) -> None:
    """Refuse a state.pt whose bytes differ from the sha256 its save recorded in meta.json (corruption)."""
    if recorded is None:
        return
    actual = hashlib.sha256(state_file.read_bytes()).hexdigest()
    if actual != recorded:
        raise ValueError(must_be(f"the sha256 of {state_file}", f"{str(recorded)[:16]}… (recorded in meta.json "
                                 "when it was saved)", f"{actual[:16]}…", "The file is corrupt or partial, or "
                                 "meta.json belongs to another save: copy or train the model again."))
