"""Active inference over any SensoryModel(s): batched perception by generalized filtering.

`Perception(models, PerceptionConfig(...)).infer(observations, mu0)` → `PerceptionResult`;
`infer_multistart` for beliefs that may start in the wrong basin. Knows only the SensoryModel protocol.
"""

from bodyschema.aif.multistart import MultiStartResult, infer_multistart
from bodyschema.aif.perception import Perception, PerceptionConfig, PerceptionResult

__all__ = ["MultiStartResult", "Perception", "PerceptionConfig", "PerceptionResult", "infer_multistart"]
