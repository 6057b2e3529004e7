"""The reaching benchmark's goals (reaching/benchmark.py): which modalities may be a goal, what the goal sensor
reads at a pose, and whether a given goal is well formed and reachable."""

from __future__ import annotations

import numpy as np
import torch

from bodyschema.base import modalities
from bodyschema.base.modalities import is_image
from bodyschema.datagen.body.reach import arm_reach
from bodyschema.errors import must_be
from bodyschema.evaluation.core.sensing import sense

GOAL_PREFERENCE = ("ee_xyz", "ee_pixel", "joints")   # "auto": the first camera among the models, else of these


def builtin_sensors(robot) -> list[str]:
    """Sensors a controller has without a model: a torque-driven arm's AIC reads its joint encoders itself."""
    return ["joints"] if robot.actuation == "torque" else []


def goal_names() -> tuple[str, ...]:
    """The goal modalities in the order "auto" prefers them: every camera's, then the vector ones."""
    return (*(m.name for m in modalities.images()), *GOAL_PREFERENCE)


def make_goal(robot, modality: str, q: np.ndarray) -> torch.Tensor:
    """What the goal sensor reads at poses q (N, Dq) rad: joints rad, ee_xyz m, ee_pixel px, image in [0, 1]."""
    return torch.from_numpy(sense(robot, modality, q))


def check_goal(robot, modality: str, goal, output_shape: tuple[int, ...]) -> None:
    """Raise the house error for a malformed goal or one the arm cannot reach (outside the joint limits, the
    arm's reach or the image)."""
    shape = tuple(getattr(goal, "shape", ()))
    if not isinstance(goal, torch.Tensor) or len(shape) != 1 + len(output_shape) or shape[1:] != tuple(output_shape):
        raise ValueError(must_be(f"{modality} goal", f"a tensor of shape (N, {', '.join(map(str, output_shape))})",
                                 shape or type(goal).__name__))
    x = goal.numpy()
    if not np.isfinite(x).all():
        raise ValueError(must_be(f"{modality} goal", "finite", "NaN or inf values"))
    if modality == "joints":
        robot.check_q(x)
    elif modality == "ee_pixel":
        h, w = robot.image_size
        outside = (x[:, 0] < 0) | (x[:, 0] > w - 1) | (x[:, 1] < 0) | (x[:, 1] > h - 1)
        if outside.any():
            raise ValueError(must_be("ee_pixel goal", f"inside the {w}×{h} px image", x[outside][0].tolist(),
                                     "A pixel the camera cannot see is not a reachable goal."))
    elif modality == "ee_xyz":
        base, reach = arm_reach(robot.model, robot.ee_site)   # a bound: a goal beyond it is unreachable
        far = np.linalg.norm(x - base, axis=1) > reach
        if far.any():
            raise ValueError(must_be("ee_xyz goal", f"within the arm's reach ({reach:.3f} m from {base.round(3)})",
                                     x[far][0].round(4).tolist(), "Pick a goal inside the workspace."))
    elif is_image(modality) and ((x < 0) | (x > 1)).any():
        raise ValueError(must_be("image goal", "intensities in [0, 1] (uint8 / 255)", (x.min(), x.max())))
