"""The gains and precisions of the active inference torque controller (aif/aic.py runs them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bodyschema.aif.priors import GEOMETRIES
from bodyschema.errors import must_be

INTEGRATORS = ("implicit", "euler")


# Tuning. Π_q, Π_q̇, Π_μ' and κ_μ are the AIC authors' Panda values (σ²_q = σ²_q̇ = 1, σ²_μ' = 10, κ_μ = 11.67; there
# also σ²_μ = 5, β = 1, κ_a = 200 at 1 kHz). κ_a, β and Π_μ were re-tuned on the simulated torque panda (4 Earth-gravity
# episodes around the ready pose, seed 7, 500 Hz): a grid (β, Π_μ) ∈ {(1, 0.2), (2, 0.5), (2, 1), (4, 1)} × κ_a ∈
# {800, 2000, 5000}, minimizing the mean joint error over 5 s. (2, 1) won (1.37° vs 2.71° for the authors' (1, 0.2));
# κ_a barely changed it (the belief's attractor sets the pace), so κ_a is the middle value: the authors' 200 let the
# Jupiter step grow to ~10° in a first trial, and the loop stays stable up to κ_a = 20000 at 250 and 500 Hz.
# Extra-model precisions add pure integral action (J_mᵀ Π_m ε_m has no velocity counterpart): Π_ee_xyz = 8 and
# 16 m⁻² left mean final errors of 0.13° and 0.79° (limit cycles) vs 0.003° at 0.
@dataclass(frozen=True)
class AICConfig:
    """Gains and precisions of the active inference torque controller (defaults tuned on the simulated panda)."""

    k_mu: float = 11.67          # κ_μ (1/s), belief gain
    k_a: float = 2000.0          # κ_a (N·m/s per unit of weighted error); κ_a Π_q̇ acts as a P gain (N·m/rad)
    pi_q: float = 1.0            # Π_q (rad⁻²), joint-position sensor; κ_a Π_q is the integral gain
    pi_qd: float = 1.0           # Π_q̇ ((rad/s)⁻²), joint-velocity sensor
    pi_mu: float = 1.0           # Π_μ, prior on μ' = f(μ): how strongly the belief is drawn to the goal
    pi_mu_d: float = 0.1         # Π_μ', prior on μ'' = A μ'
    attractor_gain: float = 2.0  # β (1/s) for a joints goal
    # β per goal modality, 1/(s·unit²): for an ee_xyz goal, 2 / 10 / 40 left 60 / 3.5 / 7.9 mm after 4 s (4 episodes)
    goal_gains: tuple[tuple[str, float], ...] = (("ee_xyz", 10.0),)
    goal_geometry: str = "gradient"   # a model goal's f: "gradient" β Jᵀ(x_d − g) | "gauss_newton" (priors.py)
    # Π of the extra models (per output), 0 = a broken sensor. Defaults give J_mᵀ Π_m J_m ≈ ½ Π_q on the panda's
    # shoulder joints (|J| ≈ 0.5 m/rad, ≈ 40 px/rad): of Π_ee_xyz ∈ {1, 2, 4} on 10 Jupiter episodes (seed 7), 4 left
    # one in a limit cycle. A modality not listed uses model.precision(μ) · model_precision_scale.
    precisions: tuple[tuple[str, float], ...] = (("ee_xyz", 2.0), ("ee_pixel", 3e-4))
    model_precision_scale: float = float(np.deg2rad(1.0) ** 2)   # maps a 1° joint σ (model units) onto Π_q = 1
    perception_steps: int = 1    # belief updates per control tick (each of dt / perception_steps)
    integrator: str = "implicit"  # "implicit" (linearly implicit Euler) | "euler" (the paper's)

    def __post_init__(self):
        for name in ("k_mu", "k_a", "pi_q", "pi_qd", "pi_mu", "pi_mu_d", "attractor_gain", "model_precision_scale"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(must_be(name, "a finite number > 0", value))
        for entry in self.precisions:
            if not (len(entry) == 2 and isinstance(entry[0], str) and np.isfinite(entry[1]) and entry[1] >= 0):
                raise ValueError(must_be("precisions", "pairs (modality, Π ≥ 0)", self.precisions))
        for entry in self.goal_gains:
            if not (len(entry) == 2 and isinstance(entry[0], str) and np.isfinite(entry[1]) and entry[1] > 0):
                raise ValueError(must_be("goal_gains", "pairs (modality, β > 0)", self.goal_gains))
        if not (isinstance(self.perception_steps, int) and self.perception_steps >= 1):
            raise ValueError(must_be("perception_steps", "an integer ≥ 1", self.perception_steps))
        if self.goal_geometry not in GEOMETRIES:
            raise ValueError(must_be("goal_geometry", f"one of {GEOMETRIES}", self.goal_geometry))
        if self.integrator not in INTEGRATORS:
            raise ValueError(must_be("integrator", f"one of {INTEGRATORS}", self.integrator))


DEFAULTS = AICConfig()                # the default of `AICController`'s config (frozen: one instance serves all)
