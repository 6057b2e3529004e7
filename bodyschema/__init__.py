"""bodyschema: a robot learns its body by motor babbling and perceives and moves it by active inference.

Subpackages (one direction of data flow): datagen → models → training → aif → evaluation.

The entry points a script needs, importable from here (each loaded on first use, so `import bodyschema` stays
fast and pulls in neither torch nor MuJoCo):

    data     = bodyschema.load_dataset("data/nao.zarr", "ee_xyz")          # validated, split train/val
    model    = bodyschema.GPRModel(data.body, "ee_xyz", (3,)).fit(data.train.q, data.train.x)
    belief   = bodyschema.Perception([model]).infer({"ee_xyz": x}, mu0)   # numpy or torch in, tensors out
    champion = bodyschema.load_registered("models:/bodyschema-nao_arm-ee_xyz-gpr@champion")

Model kinds: GPRModel, SVGPModel, SklearnGPRModel, MDNModel, PixelDecoder, MultimodalModel, ImageEncoder, AnalyticModel
(`load_model(dir)` reads any saved one). Datasets: generate / DatagenConfig, load_dataset, validate_store,
show_store, export_dataset. Models out: export_onnx. Perception: Perception, PerceptionConfig, infer_multistart;
of a stream, frame by frame: Tracker, TrackerConfig.
"""

from __future__ import annotations

import os

from bodyschema.lazy import lazy_exports

# Headless rendering by default. mujoco picks its GL backend once, when first imported, and every module of ours
# that imports it runs this package's __init__ first: the one place to set it. A value the user set wins.
if os.environ.setdefault("MUJOCO_GL", "egl") in ("egl", "osmesa"):
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"

_EXPORTS = {   # public name → module defining it (imported on first access)
    "DatagenConfig": "bodyschema.datagen.config", "generate": "bodyschema.datagen.generate",
    "validate_store": "bodyschema.datagen.store.validate", "show_store": "bodyschema.datagen.store.show",
    "export_dataset": "bodyschema.datagen.exchange.export",
    "load_dataset": "bodyschema.training.data", "Dataset": "bodyschema.training.data",
    "BodySpec": "bodyschema.models.scaling", "SensoryModel": "bodyschema.models.contract",
    "load_model": "bodyschema.models.contract",
    "GPRModel": "bodyschema.models.gpr", "SVGPModel": "bodyschema.models.svgp",
    "SklearnGPRModel": "bodyschema.models.sklearn_gpr",
    "MDNModel": "bodyschema.models.mdn", "PixelDecoder": "bodyschema.models.pixel",
    "MultimodalModel": "bodyschema.models.multimodal", "ImageEncoder": "bodyschema.models.encoder",
    "AnalyticModel": "bodyschema.models.analytic", "export_onnx": "bodyschema.models.onnx_export",
    "Perception": "bodyschema.aif.perception", "PerceptionConfig": "bodyschema.aif.perception",
    "PerceptionResult": "bodyschema.aif.perception", "infer_multistart": "bodyschema.aif.multistart",
    "Tracker": "bodyschema.aif.tracker", "TrackerConfig": "bodyschema.aif.tracker_config",
}
_RENAMED = {"load_registered": ("bodyschema.training.registry", "load")}   # registry.load: models:/<name>@<alias>

__all__, __getattr__, __dir__ = lazy_exports(
    "bodyschema", globals(),
    {**{name: (module, name) for name, module in _EXPORTS.items()}, **_RENAMED})
__all__ = sorted([*__all__, "__version__"])
