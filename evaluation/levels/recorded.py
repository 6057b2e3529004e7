"""The levels on recorded targets (`evaluate levels --targets STORE`): held-out frames of a dataset store (imported
recordings or any generated store), with their joint angles as the truth, instead of simulator renders.

The store is validated first and must hold every modality the models observe (image and/or ee readings), over the
models' body (robot name and joints, in order). Frames whose joint angles lie inside the box every model was trained
on are eligible; run r scores eligible frames r·trials … (r+1)·trials − 1 in store order, so a store holding the
poses the simulator would draw reproduces the simulator's levels (same seed: same initial beliefs). No simulator
is needed: the ee error (mm) is the forward kinematics of the store's robot when it names one that loads (MuJoCo
kinematics only, nothing rendered), else NaN. The run records the store's path and content digest (lineage).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bodyschema.base.modalities import IMAGE, images_in, is_image
from bodyschema.errors import must_be
from bodyschema.evaluation.core.specs import check_models_match, trained_workspace
from bodyschema.evaluation.levels.targets import Targets, add_noise
from bodyschema.models.scaling import IMAGE_SCALE

SENSED = ("ee_xyz", "ee_pixel")     # vector modalities read from the store, besides every camera's; "joints" is q


@dataclass
class RecordedBody:
    """What the levels ask of a robot, from a store's attrs: names, limits, the evaluation box, camera image."""

    name: str
    joint_names: tuple[str, ...]
    joint_limits: np.ndarray            # (Dq, 2) rad
    sampling_ranges: np.ndarray         # (Dq, 2) rad: set to the models' trained box
    image_size: tuple[int, int] | None
    channels: int
    robot: Any = None                   # a datagen Robot for the ee error, or None

    def fk(self, q) -> np.ndarray:
        """(N, Dq) rad → (N, 3) m of the store's robot; NaN without one."""
        q = np.asarray(q, dtype=np.float64)
        return self.robot.fk(q, check=False) if self.robot is not None else np.full((len(q), 3), np.nan)

    def close(self) -> None:
        if self.robot is not None:
            self.robot.close()


class RecordedTargets:
    """A validated store's frames as level targets for `models` (+ an encoder's image)."""

    def __init__(self, path: Path, models, image: bool):
        from bodyschema.datagen.store.reader import check_store, store_digest

        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(must_be("--targets", "an existing dataset store", str(self.path),
                                            "Import recordings with `bodyschema import` or generate a store."))
        store = check_store(self.path, what="--targets")
        if store.problems:
            raise ValueError(must_be("--targets", "a complete, valid dataset store", f"{len(store.problems)} "
                                     f"problem(s) in {self.path}",
                                     "See `bodyschema validate`:\n - " + "\n - ".join(store.problems)))
        root = store.root
        self.attrs, self.digest = dict(root.attrs), store_digest(root)
        wanted = {m.modality for m in models if m.modality in SENSED or is_image(m.modality)}
        wanted |= {IMAGE} if image else set()                                     # the encoder's
        missing = sorted(wanted - set(root.array_keys()))
        if missing:
            raise ValueError(must_be(f"--targets arrays {missing}", "in the store (the models observe them)",
                                     sorted(root.array_keys()), "Import or generate the targets with them."))
        self.q = np.asarray(root["q"][:], dtype=np.float64)                        # (N, Dq) rad
        self.sensed = {m: np.asarray(root[m][:]) for m in sorted(wanted)}
        self.body = self._body(models)
        low, high = self.body.sampling_ranges.T
        self.eligible = np.flatnonzero(((self.q >= low) & (self.q <= high)).all(axis=1))

    def _body(self, models) -> RecordedBody:
        a = self.attrs
        cameras = images_in(self.sensed)
        image = self.sensed[cameras[0]] if cameras else None
        body = RecordedBody(str(a["robot"]), tuple(a["joint_names"]), np.asarray(a["joint_limits"], float),
                            np.asarray(a["joint_limits"], float), None if image is None else tuple(image.shape[1:3]),
                            3 if image is not None and image.ndim == 4 else 1, _robot_of(a))
        check_models_match(models, body)
        for m in models:
            frame = self.sensed[m.modality].shape[1:] if is_image(m.modality) else None
            if frame is not None and tuple(m.output_shape) != tuple(frame):
                raise ValueError(must_be("--targets images", f"of the image model's shape {tuple(m.output_shape)}",
                                         tuple(frame), "Import them with --resize (and --gray)."))
        body.sampling_ranges = trained_workspace(models, body)
        return body

    def check_enough(self, trials: int, runs: int) -> None:
        if len(self.eligible) < trials * runs:
            raise ValueError(must_be("--targets frames inside the models' joint box", f"at least trials × runs = "
                                     f"{trials * runs}", f"{len(self.eligible)} of {len(self.q)}",
                                     f"Pass --trials and --runs with trials × runs ≤ {len(self.eligible)}."))

    def run(self, run: int, trials: int, noise=None, noise_rng=None) -> Targets:
        """Run `run`'s frames: q (trials, Dq) rad and the observations in the levels' units (image in [0, 1])."""
        rows = self.eligible[run * trials:(run + 1) * trials]
        obs = {"joints": self.q[rows].copy()}
        for name, values in self.sensed.items():
            obs[name] = values[rows].astype(np.float64) / (IMAGE_SCALE if is_image(name) else 1.0)
        return Targets(self.q[rows].copy(), add_noise(obs, noise, noise_rng))

    def lineage(self) -> dict[str, Any]:
        """What the run records of its targets: the store, its content digest, its robot and source."""
        return {"path": str(self.path.resolve()), "sha256": self.digest, "robot": self.attrs.get("robot"),
                "frames": len(self.q), "eligible": len(self.eligible), "sampler": self.attrs.get("sampler"),
                "source": self.attrs.get("source")}


def _robot_of(attrs: dict):
    """The store's robot for forward kinematics when it loads (its own record and model text, or a shipped robot's
    name), else None."""
    from bodyschema.datagen.body.robot import Robot

    try:
        robot = Robot.from_attrs(attrs, image_size=None)          # the record's camera size: only FK is asked
    except (ValueError, OSError):
        return None
    if tuple(robot.joint_names) != tuple(attrs["joint_names"]):
        robot.close()
        return None
    return robot


def plain_verdict(table) -> str:
    """One line per level scored both ways: the default update's and plain Pixel-AIF's mean joint error, and which
    wins (lower mean error) on the same frames and initial beliefs. Empty without plain rows."""
    from bodyschema.evaluation.levels.plain import PLAIN_LABEL

    by_level = {str(row["level"]): row for row in table}
    lines = []
    for label, plain in by_level.items():
        level = label.removesuffix(f" {PLAIN_LABEL}")
        if level == label or level not in by_level:
            continue
        fast, slow = by_level[level]["joint_err_deg"], plain["joint_err_deg"]
        winner = PLAIN_LABEL if slow < fast else "the default update"
        lines.append(f"- level {level}: default update {fast:.3f}° vs {PLAIN_LABEL} {slow:.3f}° mean joint error "
                     f"→ {winner} wins")
    return "\n".join(lines)
