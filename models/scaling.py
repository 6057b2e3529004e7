"""Body specification of a model: which robot and joints its latent z is, and the z ↔ [-1, 1] scaling.

Callers always pass joint angles in rad; models scale internally so that their kernels and networks see
inputs in [-1, 1]. The scaling is part of the saved model state, never the caller's business.
A robot that is not shipped travels with the body (`source`: its record and model file, as a store keeps them), so a
saved model finds its robot with no path that may have moved (`models.body_robot.body_robot`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from bodyschema.errors import must_be

IMAGE_SCALE = 255.0   # images are stored uint8; every image model sees intensity x / IMAGE_SCALE in [0, 1]


@dataclass(frozen=True)
class BodySpec:
    robot: str                      # robot name, e.g. "nao_arm"
    joint_names: tuple[str, ...]    # one per latent dimension, in order
    q_low: tuple[float, ...]        # rad, lower end of the scaled range
    q_high: tuple[float, ...]       # rad, upper end of the scaled range
    # None: a shipped robot, found by its name; else the robot attrs of `datagen.body.attrs` (the record and the
    # model file's text, sha256 and mesh digests) it is rebuilt from. Not hashed: a dict (the name stands for it).
    source: dict | None = field(default=None, hash=False)

    def __post_init__(self):
        n = len(self.joint_names)
        if len(self.q_low) != n or len(self.q_high) != n:
            raise ValueError(must_be("q_low and q_high", f"of length {n} (one per joint)",
                                     (len(self.q_low), len(self.q_high))))
        if any(h <= lo for lo, h in zip(self.q_low, self.q_high)):
            raise ValueError(must_be("q_high", "greater than q_low for every joint",
                                     list(zip(self.q_low, self.q_high))))

    @property
    def latent_dim(self) -> int:
        return len(self.joint_names)

    def to_unit(self, q: torch.Tensor) -> torch.Tensor:
        """rad → [-1, 1] (affine, per joint). # (B, Dz) → (B, Dz)"""
        low, high = self._bounds(q)
        return 2.0 * (q - low) / (high - low) - 1.0

    def from_unit(self, u: torch.Tensor) -> torch.Tensor:
        """[-1, 1] → rad. # (B, Dz) → (B, Dz)"""
        low, high = self._bounds(u)
        return low + (u + 1.0) * 0.5 * (high - low)

    def unit_per_rad(self, like: torch.Tensor) -> torch.Tensor:
        """d(unit)/d(rad) per joint, the chain-rule factor for Jacobians. # (Dz,)"""
        low, high = self._bounds(like)
        return 2.0 / (high - low)

    def check_compatible(self, other: "BodySpec", what: str = "model") -> None:
        """Raise when `other` describes another robot or joint set than this spec."""
        if (self.robot, self.joint_names) != (other.robot, other.joint_names):
            raise ValueError(must_be(f"{what} body", f"robot {self.robot!r} with joints {list(self.joint_names)}",
                                     f"robot {other.robot!r} with joints {list(other.joint_names)}",
                                     "Load a model trained on the same robot and joint set."))

    def to_dict(self) -> dict:
        """As saved in meta.json; a shipped robot's body has no `source` key (saved as before it existed)."""
        out = {"robot": self.robot, "joint_names": list(self.joint_names),
               "q_low": list(self.q_low), "q_high": list(self.q_high)}
        return out if self.source is None else {**out, "source": self.source}

    @classmethod
    def from_dict(cls, d: dict) -> "BodySpec":
        return cls(d["robot"], tuple(d["joint_names"]), tuple(map(float, d["q_low"])),
                   tuple(map(float, d["q_high"])), d.get("source"))

    def _bounds(self, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        low = torch.tensor(self.q_low, dtype=like.dtype, device=like.device)
        high = torch.tensor(self.q_high, dtype=like.dtype, device=like.device)
        return low, high
