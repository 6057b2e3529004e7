"""The one precision rule of perception: the Π_x each model is perceived at, for every caller (`Perception`, goal
inference, every benchmark).

1. A precision the user names (`--perception.precisions m Π`, `Perception(..., precisions=)`) wins; 0 = a broken
   sensor.
2. A model whose precision varies with the pose (`precision_varies`: a GP's 1/predictive variance, an MDN's
   mixture) is perceived at its sensor's precision, `model.sensor_precision` (the modality's default,
   base/modalities.py: σ = 1 mm, 1 px, 1°; a model without one keeps its own).
3. Any other model keeps its own precision: an exact model's fixed sensor noise (analytic FK), a decoder's calibrated
   noise (constant over the pose).

Why (2), measured on GPRs of ee_xyz at level 1, 100 trials (bench: levels with `--perception.precisions`): with the
GP's own Π(μ) the flow stops far from F's minimum, it does not find a different one. F = ½ Π(μ) ε² − ½ ln Π(μ), and
Π(μ) ~ 1/σ²_noise ≈ 1e9–1e10 m⁻² on nao_arm and the UR5 swings 3–10× between training poses: ε² · Π(μ) gets
spurious minima where Π dips (between training poses, at the box's edge) that hold the belief 12–31 mm off the
reading, at F ~ 1e5 where the truth has F ~ −30 (96–100 % of trials end above F at the truth). The same Π frozen at
the start belief (`precision_update="initial"`) or any constant (1e3, 1e6) gives the same, correct answer (nao_arm
0.81°, UR5 1.02°, 0.000 mm off the reading): with one modality the level of Π does not matter, its variation does.
So the rule replaces a varying Π by a constant one; the sensor's, because beside other senses (the joint encoders
in reaching) the weight must be the reading's noise, not the GP's interpolation error (1e3× smaller on nao_arm).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch


def sensor_precision(model) -> float | None:
    """The precision rule (2) gives `model`, or None where it keeps its own (rules 1 and 3 aside)."""
    if not getattr(model, "precision_varies", False):
        return None
    pi = getattr(model, "sensor_precision", None)
    return None if pi is None else float(pi)


def perceived_precisions(models: Sequence, given: Mapping[str, float | torch.Tensor] | None = None
                         ) -> dict[str, float | torch.Tensor]:
    """modality → fixed Π for perception over `models`: `given` where it names the modality, else the sensor's for
    a model whose precision varies with the pose; a modality left out keeps its model's own `precision(μ)`."""
    given = dict(given or {})
    ruled = {m.modality: sensor_precision(m) for m in models if m.modality not in given}
    return {**{k: v for k, v in ruled.items() if v is not None}, **given}
