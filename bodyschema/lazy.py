"""Lazy package exports: a package's public names, each imported from its module on first access (PEP 562), so
importing the package stays cheap (no torch, MuJoCo or MLflow until a name that needs them is used)."""

from __future__ import annotations

import importlib
from collections.abc import Callable


def lazy_exports(package: str, namespace: dict, exports: dict[str, tuple[str, str]]
                 ) -> tuple[list[str], Callable[[str], object], Callable[[], list[str]]]:
    """(__all__, __getattr__, __dir__) for `package`. exports: public name → (module, attribute in it).
    A name is cached in the package's namespace once loaded: the next access is a plain attribute."""
    public = sorted(exports)

    def getattr_(name: str):
        if name not in exports:
            raise AttributeError(f"module {package!r} has no attribute {name!r}. Public names: {', '.join(public)}")
        module, attribute = exports[name]
        value = getattr(importlib.import_module(module), attribute)
        namespace[name] = value
        return value

    def dir_() -> list[str]:
        return sorted({*namespace, *public})

    return public, getattr_, dir_
