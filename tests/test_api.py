"""The public Python API: lazy top-level names, numpy at the edges, defaults equal to the CLI's, and the README
example executed as written (extracted from README.md, so the two cannot drift)."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import bodyschema

README = Path(__file__).resolve().parents[1] / "README.md"
MARKER = "<!-- example: python-api"


def readme_example() -> str:
    text = README.read_text()
    assert MARKER in text, "README.md lost its Python API example"
    match = re.search(r"```python\n(.*?)```", text[text.index(MARKER):], re.S)
    return match.group(1)


def test_the_readme_example_runs_as_written(tmp_path, monkeypatch, capsys):
    from bodyschema.datagen.config import DatagenConfig
    from bodyschema.datagen.generate import generate

    generate(DatagenConfig(robot="nao_arm", n=300, images=False, out=tmp_path / "data" / "nao.zarr"), progress=False)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(readme_example(), str(README), "exec"), namespace)    # noqa: S102 - our own README's code
    printed = capsys.readouterr().out
    assert "10 converged" in printed
    result = namespace["result"]
    assert result.converged.all() and not result.diverged.any()
    assert np.median(namespace["seen_error_mm"]) < 1.0                   # the belief explains what was seen


def test_import_is_lazy_and_names_are_discoverable():
    code = ("import sys, bodyschema; print([m for m in ('torch', 'mujoco', 'gpytorch', 'mlflow') if m in sys.modules]);"
            "print(set(bodyschema.__all__) <= set(dir(bodyschema)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"}).stdout.split("\n")
    assert out[0] == "[]", "import bodyschema must not import the heavy libraries"
    assert out[1] == "True"
    for name in ("load_dataset", "GPRModel", "MDNModel", "PixelDecoder", "MultimodalModel", "ImageEncoder",
                 "Perception", "PerceptionConfig", "load_registered", "export_dataset", "export_onnx"):
        assert getattr(bodyschema, name) is not None
    from bodyschema.training.registry import load
    assert bodyschema.load_registered is load
    with pytest.raises(AttributeError, match="Public names: .*GPRModel"):
        bodyschema.GPRModle  # noqa: B018 - the typo is the point


def test_perception_takes_numpy_and_equals_the_tensor_run():
    from tests.toy_models import ToyPlanarArm

    arm = ToyPlanarArm()
    q = torch.tensor([[0.3, 0.8], [-0.5, 1.2]], dtype=torch.float64)
    mu0 = q + 0.1
    obs = arm.predict(q)
    with_tensors = bodyschema.Perception([arm]).infer({"ee_xyz": obs}, mu0)
    with_numpy = bodyschema.Perception([arm]).infer({"ee_xyz": obs.numpy()}, mu0.numpy())
    torch.testing.assert_close(with_numpy.mu, with_tensors.mu, rtol=0, atol=0)
    assert with_numpy.converged.all()


def test_api_defaults_equal_the_clis():
    """`PerceptionConfig()` is what `evaluate levels` runs (its record flag aside); a model kind's constructor
    defaults are `bodyschema train KIND`'s config defaults."""
    from bodyschema.evaluation.levels.benchmark import LevelsConfig
    from bodyschema.models import kinds

    cli = dataclasses.replace(LevelsConfig().perception, record=False)
    api = bodyschema.PerceptionConfig()
    assert api.descends == cli.descends and dataclasses.replace(api, flow=cli.flow) == cli
    import inspect
    for name, kind in kinds.KINDS.items():
        if kind.config is None:
            continue
        params = inspect.signature(getattr(bodyschema, kind.trains)).parameters
        for f in dataclasses.fields(kind.config):
            if f.name in params and f.default is not dataclasses.MISSING:
                default = params[f.name].default
                assert f.default == (tuple(default) if isinstance(default, list) else default), (name, f.name)
