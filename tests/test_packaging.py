"""The distribution maps every subpackage: a folder missing from pyproject still imports in editable mode but
is absent from a regular install, with no warning."""

import tomllib
from importlib import resources
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP_LEVEL = ("bodyschema", "datagen", "models", "training", "aif", "evaluation", "envs", "control")


def _pyproject():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_every_folder_with_init_is_a_listed_package():
    setuptools = _pyproject()
    folder_of = {pkg: Path(folder) for pkg, folder in setuptools["package-dir"].items()}
    expected = set()
    for top in TOP_LEVEL:
        for init in (ROOT / top).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / top)
            base = next(p for p, f in folder_of.items() if f == Path(top))
            expected.add(".".join([base, *rel.parts]))
    missing = expected - set(setuptools["packages"])
    assert not missing, f"packages missing from pyproject.toml [tool.setuptools] packages: {sorted(missing)}"


def test_robot_models_ship_as_package_data():
    robots = resources.files("bodyschema.datagen") / "robots"
    names = {p.name for p in robots.iterdir()}
    assert {"planar2.xml", "nao_arm.xml", "panda.xml"} <= names


def test_the_package_is_marked_typed():
    """PEP 561: `py.typed` in the top package (every subpackage installs under it), shipped as package data."""
    assert (resources.files("bodyschema") / "py.typed").is_file()
    assert "py.typed" in _pyproject()["package-data"]["bodyschema"]
