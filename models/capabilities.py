"""What a model kind can do, declared once on its class: training, export and the CLI read these attributes.

Every model class (a `BaseSensoryModel`, the image encoder, the multimodal trainer) inherits `Capabilities` and
overrides the flags that are true of it, next to its code, so a new kind needs no table elsewhere:
- `exports_onnx`: `models/onnx_export.py` traces it (its hooks are pure torch); else `onnx_hint` says what to do;
- `convolutional`: its graph has Conv layers, exported in float32 (onnxruntime's CPU provider has no float64 Conv);
- `gp_memory`: an exact GP, refused by `training/guards.py` when its n×n matrices cannot fit in memory;
- `network`: fitted on minibatches from `_factory()` and `settings.batch_size`, guarded by its size;
- `has_members`: several SensoryModels over one z in `members` {modality: model}, registered one per modality;
- `encodes`: the inverse map, images → z (`encode`), scored on joint angles and exported from images;
- `sweepable`: one decoder scored by its val_rmse, what `bodyschema sweep` minimises (a kind scored otherwise,
  e.g. on members or joint angles, is trained by `bodyschema train`);
- `exact`: the true map (forward kinematics), whose only error is the sensor's noise: Π = 1/σ² under noise σ.
This module imports nothing heavy: the CLI and the registry may read it before torch is loaded.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar


@dataclass(frozen=True)
class GPMemory:
    """Peak memory of an exact GP fit in float64 copies of its n×n (or m×m) matrix, measured (training/guards.py)."""

    fit_copies: float          # while fitting the hyper-parameters on m samples
    condition_copies: float    # while conditioning on n samples
    per_output: bool           # one kernel per output dimension (True) or one shared by all outputs


class Capabilities:
    """The flags of the module doc, all off: a kind's class turns on what it does."""

    kind: ClassVar[str] = "base"
    exports_onnx: ClassVar[bool] = False
    onnx_hint: ClassVar[str] = ""
    convolutional: ClassVar[bool] = False
    gp_memory: ClassVar[GPMemory | None] = None
    network: ClassVar[bool] = False
    has_members: ClassVar[bool] = False
    encodes: ClassVar[bool] = False
    sweepable: ClassVar[bool] = False
    exact: ClassVar[bool] = False
