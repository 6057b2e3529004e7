"""`AnalyticModel`: the robot's exact MuJoCo forward kinematics as a SensoryModel — the oracle.

x = g(z) for z = joint angles (rad): the `ee` site position (ee_xyz, m), its orientation (ee_rot, its rotation
matrix row by row), its camera projection (ee_pixel, px; ee_pixel_<camera> into a further camera of the record)
or the joints themselves (joints, rad, identity). The Jacobian is closed-form: mj_jacSite (its hinge recursion
vectorized over the batch for large B, equal to 1e-12), chained with the pinhole projection Jacobian for ee_pixel;
for ee_rot each hinge's turn of the rotation, [a_j]× R. Precision is fixed. Nothing is learned, so saving stores the
config and the body only, and loading rebuilds the robot as every stage does (`body_robot`): a shipped robot from
its shipped MJCF (a changed MJCF is reported on load), a robot from a file from the record and model text its body
carries.
The FK is evaluated for any finite z, also outside the joint limits, since inference may probe there.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch

from bodyschema.base import modalities
from bodyschema.datagen.body.robot import Robot
from bodyschema.errors import must_be
from bodyschema.models.body_robot import body_robot, robot_source
from bodyschema.models.contract import BaseSensoryModel, register_kind
from bodyschema.models.scaling import BodySpec

MODALITIES = modalities.KINEMATIC
# Default diagonal precisions Π_x, the table's (σ = 1 mm, 1 px, 1°).
DEFAULT_PRECISION = {m: modalities.MODALITIES[m].precision for m in MODALITIES}


@register_kind
class AnalyticModel(BaseSensoryModel):
    """Exact FK of a robot: ee_xyz (3,) m, ee_rot (9,), ee_pixel (2,) px or joints (Dq,) rad, fixed precision.

    robot: a shipped name, a path to an MJCF/URDF/record, or another model's BodySpec (its robot: `body_robot`;
    the latent scaling is the robot's camera workspace either way)."""

    kind = "analytic"
    exact = True
    onnx_hint = "MuJoCo's forward kinematics has no tensor graph: export the robot's MJCF instead"

    def __init__(self, robot: str | Path | BodySpec, modality: str, image_size: tuple[int, int] | None = None,
                 precision: float | None = None):
        projection = modalities.is_projection(modality)          # ee_pixel or ee_pixel_<camera>
        if modality not in MODALITIES and not projection:
            raise ValueError(must_be("modality", f"one of {MODALITIES} or ee_pixel_<camera>", modality))
        default = DEFAULT_PRECISION[modalities.EE_PIXEL if projection else modality]
        precision = default if precision is None else precision
        if not (isinstance(precision, (int, float)) and np.isfinite(precision) and precision > 0):
            raise ValueError(must_be("precision", "a finite number > 0 (1 / variance of x)", precision,
                                     f"The default for {modality} is {default:.6g}."))
        # cheap: no renderer until render()
        self.robot = (body_robot(robot, image_size) if isinstance(robot, BodySpec)
                      else Robot.load(robot, image_size=image_size))
        if projection and modality not in self.robot.projections():
            raise ValueError(must_be("modality", f"one of {self.robot.name}'s projections "
                                     f"{list(self.robot.projections())}", modality,
                                     "Name further cameras in the robot record's `cameras`."))
        low, high = self.robot.sampling_ranges.T
        body = BodySpec(self.robot.name, self.robot.joint_names, tuple(map(float, low)), tuple(map(float, high)),
                        robot_source(self.robot))
        super().__init__(body, modality, modalities.shape_of(modality, self.robot.dq))
        self.image_size = self.robot.image_size if projection else None
        self.fixed_precision = float(precision)

    # ---- hooks ----------------------------------------------------------------------------------------
    def _predict(self, z: torch.Tensor) -> torch.Tensor:
        if self.modality == "joints":
            return z.clone()
        if self.modality == "ee_rot":
            return torch.from_numpy(self.robot.ee_rot(_numpy(z), check=False)).to(z)
        q = _numpy(z)                                                     # (B, Dz) rad, float64
        xyz = self.robot.fk(q, check=False)                               # (B, 3) m
        x = self.robot.project(xyz, self.modality) if self.image_size else xyz   # (B, 2) px | (B, 3) m
        return torch.from_numpy(x).to(device=z.device, dtype=z.dtype)

    def _jacobian(self, z: torch.Tensor) -> torch.Tensor:
        if self.modality == "joints":
            eye = torch.eye(self.latent_dim, dtype=z.dtype, device=z.device)
            return eye.expand(z.shape[0], -1, -1).clone()                 # (B, Dz, Dz)
        if self.modality == "ee_rot":
            return torch.from_numpy(self.robot.ee_rot_and_jacobian(_numpy(z), check=False)[1]).to(z)   # (B, 9, Dz)
        xyz, jac = self.robot.fk_and_jacobian(_numpy(z), check=False)     # (B, 3) m, (B, 3, Dz) m/rad
        if self.image_size:                                               # a projection: px/m @ m/rad
            jac = self.robot.project_jacobian(xyz, self.modality) @ jac   # (B, 2, 3) @ (B, 3, Dz) → (B, 2, Dz)
        return torch.from_numpy(jac).to(device=z.device, dtype=z.dtype)

    def _precision(self, z: torch.Tensor) -> torch.Tensor:
        return torch.full((z.shape[0], *self.output_shape), self.fixed_precision, dtype=z.dtype, device=z.device)

    # ---- persistence ------------------------------------------------------------------------------------
    def _config(self) -> dict:
        return {"robot": self.robot.name, "modality": self.modality,
                "image_size": list(self.image_size) if self.image_size else None,
                "precision": self.fixed_precision, "mjcf_sha256": self.robot.mjcf_sha256}

    @classmethod
    def _from_saved(cls, body, modality, output_shape, config, state):
        size = tuple(config["image_size"]) if config.get("image_size") else None
        model = cls(body, config["modality"], size, config["precision"])
        body.check_compatible(model.body, "saved analytic model")
        if config.get("mjcf_sha256") not in (None, model.robot.mjcf_sha256):
            warnings.warn(f"The shipped MJCF of {config['robot']!r} changed since this model was saved "
                          f"(sha256 {config['mjcf_sha256'][:12]}… → {model.robot.mjcf_sha256[:12]}…); "
                          "the oracle now follows the new MJCF.", stacklevel=3)
        return model


def _numpy(z: torch.Tensor) -> np.ndarray:
    return z.detach().to("cpu", torch.float64).numpy()                   # (B, Dz) rad
