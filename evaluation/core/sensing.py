"""The one sensing function of the benchmarks: what a sensor of each modality reads with the arm at poses q.

    joints    q, rad
    ee_xyz    the end-effector (or the visual marker, when its simulated position is given) in the world, m
    ee_rot    the end-effector's orientation, its rotation matrix row by row (the marker moves, it does not turn)
    ee_pixel  its projection in the robot camera, px (NaN for a point that left the scene); ee_pixel_<c> in a
              further camera c
    image     the camera image as intensity in [0, 1] scaled as the training data, the marker geom moved by
              per-row offsets (hand frame, m) when given; image_<c>: a further camera c's
`Sensors` adds what the loop benchmarks vary: Gaussian noise σ per modality and streams frozen at their first value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from bodyschema.base.modalities import is_image, is_projection
from bodyschema.models.contract import FUSED_CALLS
from bodyschema.models.scaling import IMAGE_SCALE


def sense(robot, modality: str, q: np.ndarray, xyz: np.ndarray | None = None,
          marker_offsets: np.ndarray | None = None, image_dtype=np.float64) -> np.ndarray:
    """What a `modality` sensor reads at poses q (N, Dq) rad → (N, *out). xyz (N, 3) m: the simulated point the
    camera tracks (default: the ee by forward kinematics). image_dtype float32 halves long image streams."""
    if modality == "joints":
        return np.asarray(q, dtype=np.float64)
    if is_image(modality):
        return _image(robot, modality, q, marker_offsets, image_dtype)
    if modality == "ee_rot":
        return robot.ee_rot(q, check=False)
    xyz = robot.fk(q, check=False) if xyz is None else xyz                # (N, 3) m; q may pass the limits
    if is_projection(modality):
        return _project(robot, modality, xyz)
    return np.asarray(xyz, dtype=np.float64)


def sense_all(robot, modalities: Sequence[str], q: np.ndarray, xyz: np.ndarray | None = None,
              marker_offsets: np.ndarray | None = None) -> dict[str, torch.Tensor]:
    """`sense` for several modalities at once (forward kinematics done once) as float64 tensors."""
    if xyz is None and any(m == "ee_xyz" or is_projection(m) for m in modalities):
        xyz = robot.fk(q, check=False)
    return {m: torch.from_numpy(np.asarray(sense(robot, m, q, xyz, marker_offsets), dtype=np.float64))
            for m in modalities}


def _project(robot, modality: str, xyz: np.ndarray) -> np.ndarray:
    """robot.project, with points that left the scene (non-finite) seen as NaN: their episodes fail."""
    out = np.full((len(xyz), 2), np.nan)
    ok = np.isfinite(xyz).all(axis=1)
    if ok.any():
        out[ok] = robot.project(xyz[ok], modality)
    return out


def _image(robot, modality: str, q: np.ndarray, offsets: np.ndarray | None, dtype) -> np.ndarray:
    q = np.clip(q, robot.joint_limits[:, 0], robot.joint_limits[:, 1])    # a simulated arm may pass its limits
    if offsets is None or not np.any(offsets):
        return robot.render(q, modality=modality).astype(dtype) / dtype(IMAGE_SCALE)
    geom = robot.model.geom("marker").id
    home = robot.model.geom_pos[geom].copy()
    frames = []
    try:
        for q_i, off in zip(q, offsets):
            robot.model.geom_pos[geom] = home + off
            frames.append(robot.render(q_i[None], modality=modality)[0])
    finally:
        robot.model.geom_pos[geom] = home
    return np.stack(frames).astype(dtype) / dtype(IMAGE_SCALE)


@dataclass
class Sensors:
    """What a controller senses of an ArmBatch: noise σ per modality (its units: rad, m, px, intensity) and
    streams frozen at their first reading."""

    modalities: tuple[str, ...]
    noise: Mapping[str, float] = field(default_factory=dict)
    frozen: frozenset[str] = frozenset()
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    _held: dict = field(default_factory=dict)

    def read(self, arm) -> dict[str, torch.Tensor]:
        fresh = [m for m in self.modalities if m not in self._held]
        out = sense_all(arm.robot, fresh, arm.q, arm.ee_xyz) if fresh else {}
        for name in fresh:
            sigma = self.noise.get(name, 0.0)
            if sigma > 0:
                x = out[name].numpy() + sigma * self.rng.standard_normal(tuple(out[name].shape))
                out[name] = torch.from_numpy(np.clip(x, 0.0, 1.0) if is_image(name) else x)
            if name in self.frozen:
                self._held[name] = out[name]
        return {name: self._held.get(name, out.get(name)) for name in self.modalities}


def through_noise(models: Sequence, sigma: Mapping[str, float], given: Mapping[str, float]
                  ) -> tuple[list, dict[str, float]]:
    """The models as sensors with additive noise σ per modality see them, and the precisions that follows. An exact
    (analytic) model's only error is the noise: Π = 1/σ²; so is a model whose precision varies with the pose, which
    perception sees at its sensor's precision (aif/precisions.py), here the simulated sensor's. A learned model's
    constant precision covers its own error, the noise adds to it: Π = 1/(1/Π_model + σ²) (`NoisySensor`). A modality
    in `given` keeps its given precision (its model left as it is); → the models, the precisions set here (not
    `given`)."""
    fixed, seen = {}, []
    for m in models:
        s = sigma.get(m.modality, 0.0)
        exact = getattr(m, "exact", False) or getattr(m, "precision_varies", False) or m.modality in given
        if s > 0 and exact and m.modality not in given:
            fixed[m.modality] = 1.0 / s ** 2
        seen.append(NoisySensor(m, s) if s > 0 and not exact else m)
    return seen, fixed


class NoisySensor:
    """A SensoryModel observed through additive sensor noise σ: precision 1/(1/Π(μ) + σ²); the rest delegated."""

    def __init__(self, model, sigma: float):
        self.model, self.variance = model, float(sigma) ** 2
        self.body, self.latent_dim, self.modality = model.body, model.latent_dim, model.modality
        self.output_shape, self.kind = model.output_shape, getattr(model, "kind", type(model).__name__)
        if hasattr(model, "compute_dtype"):                         # a network keeps its fast float32 path
            self.compute_dtype = model.compute_dtype

    def __getattr__(self, name):
        """The model's optional fused calls (`FUSED_CALLS`), where it has them: the noise changes only the precision,
        and free energy asks for them with hasattr (a network's Gauss–Newton step then runs one forward, not two)."""
        if name in FUSED_CALLS and "model" in self.__dict__:
            return getattr(self.__dict__["model"], name)
        raise AttributeError(name)

    def predict(self, z):
        return self.model.predict(z)

    def jacobian(self, z):
        return self.model.jacobian(z)

    def vjp(self, z, v):
        return self.model.vjp(z, v)

    def precision(self, z):                                         # (B, *out) output units⁻²
        return 1.0 / (1.0 / self.model.precision(z) + self.variance)

    def save(self, path):
        self.model.save(path)
