"""The control layer is the floor: envs/ stands on it and never on a benchmark (as dm_control's suite stands on its
physics, and agents on the suite), and control/ stands on neither envs/, evaluation/ nor training/. Read from the
source with `ast` (tests/import_graph.py): an import inside a function counts as one at the top."""

from __future__ import annotations

import pytest

from tests import import_graph

FORBIDDEN = {"envs": ("evaluation",), "control": ("envs", "evaluation", "training")}


@pytest.fixture(scope="module")
def found() -> list[import_graph.Import]:
    return import_graph.imports(import_graph.package_modules())


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_a_layer_imports_nothing_above_it(layer, found):
    bad = [f"{i.source}:{i.line} imports {i.target}" for i in found
           if import_graph.stage(i.source) == layer and import_graph.stage(i.target) in FORBIDDEN[layer]]
    assert not bad, f"{layer}/ must not import {FORBIDDEN[layer]}:\n" + "\n".join(bad)


def test_the_check_sees_a_function_level_import(tmp_path):
    """The graph reads imports inside functions and resolves relative ones (one hidden there is found)."""
    (tmp_path / "pyproject.toml").write_text('[tool.setuptools.package-dir]\n"bodyschema.envs" = "envs"\n'
                                             '"bodyschema.evaluation" = "evaluation"\n')
    for folder in ("envs", "evaluation"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "__init__.py").write_text("")
    (tmp_path / "evaluation" / "bench.py").write_text("from . import helper\n")
    (tmp_path / "evaluation" / "helper.py").write_text("")
    (tmp_path / "envs" / "env.py").write_text("def f():\n    from bodyschema.evaluation import bench\n")
    found = import_graph.imports(import_graph.package_modules(tmp_path))
    assert {(i.source, i.target, i.in_function) for i in found} == {
        ("bodyschema.envs.env", "bodyschema.evaluation.bench", True),
        ("bodyschema.evaluation.bench", "bodyschema.evaluation.helper", False)}
