"""The package's module import graph, read from the source with `ast` (nothing is imported): every `import` and
`from ... import` at any nesting level (module top, functions, classes, branches), relative imports resolved, each
folder named by pyproject.toml's package-dir (`datagen/body/robot.py` is `bodyschema.datagen.body.robot`).

An edge goes to the deepest module the statement names: `from bodyschema.evaluation.reaching import goal_pose` to
`...reaching.goal_pose`, `from bodyschema.evaluation.reaching import run_reaching` to the package `...reaching`.
The parent packages Python initializes on the way are not edges: a package's `__init__` exporting its own modules
would otherwise form a cycle with each of them. Lazy exports (`bodyschema.lazy`, module names as strings) are not
imports either: they load on first use, after every import has finished.
"""

from __future__ import annotations

import ast
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Import:
    source: str          # the importing module
    target: str          # the imported module (of the package)
    in_function: bool    # inside a function body (run when it is called, not when the module loads)
    line: int


def package_modules(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the package → its file, named through pyproject.toml's package-dir."""
    folders = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    modules = {}
    for package, folder in folders.items():
        for path in sorted((root / folder).rglob("*.py")):
            parts = path.relative_to(root / folder).with_suffix("").parts
            if "__pycache__" in parts:
                continue
            name = ".".join([package, *parts[:-1]] + ([] if parts[-1] == "__init__" else [parts[-1]]))
            modules.setdefault(name, path)        # a nested package-dir maps its own folder first
    return modules


def imports(modules: dict[str, Path]) -> list[Import]:
    """Every import of one package module by another, at any nesting level."""
    found = []
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(), str(path))
        for node, in_function in _import_nodes(tree):
            for target in _targets(node, package, modules):
                if target != name:
                    found.append(Import(name, target, in_function, node.lineno))
    return found


def graph(found: list[Import]) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for i in found:
        edges.setdefault(i.source, set()).add(i.target)
        edges.setdefault(i.target, set())
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (a path that comes back to its start) per strongly connected component of more than one module."""
    return [_cycle_in(component, edges) for component in _components(edges) if len(component) > 1]


def stage(module: str) -> str:
    """A module's stage: the top-level subpackage (`bodyschema.datagen.body.robot` → datagen), or bodyschema itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in _STAGES) else parts[0]


_STAGES = {"datagen", "models", "training", "aif", "evaluation", "envs", "control", "reproduce"}


def _import_nodes(tree: ast.AST):
    """(node, inside a function) for every import statement of the tree."""
    stack = [(tree, False)]
    while stack:
        node, in_function = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node, in_function
        inner = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        stack.extend((child, inner) for child in ast.iter_child_nodes(node))


def _targets(node, package: str, modules: dict[str, Path]) -> list[str]:
    if isinstance(node, ast.Import):
        return [t for t in (_deepest(a.name, modules) for a in node.names) if t]
    base = node.module or ""
    if node.level:
        anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
        base = ".".join(anchor + ([base] if base else []))
    named = [_deepest(f"{base}.{a.name}", modules) for a in node.names]
    return [t for t in (named if any(named) else [_deepest(base, modules)]) if t]


def _deepest(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of a dotted name that is a package module (None outside the package)."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        if ".".join(parts[:end]) in modules:
            return ".".join(parts[:end])
    return None


def _components(edges: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components, iteratively (the graph is deep enough for Python's recursion)."""
    index, low, on_stack, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    out.append(sorted(component))
            elif child not in index:
                index[child] = low[child] = counter[0]
                counter[0] += 1
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(sorted(edges[child]))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return out


def _cycle_in(component: list[str], edges: dict[str, set[str]]) -> list[str]:
    """The shortest path from the component's first module back to itself (breadth first, inside the component)."""
    start, inside = component[0], set(component)
    parent, frontier = {start: None}, [start]
    while frontier:
        following = []
        for node in frontier:
            for child in sorted(edges[node] & inside):
                if child == start:
                    path = [node]
                    while parent[path[-1]] is not None:
                        path.append(parent[path[-1]])
                    return [*reversed(path), start]
                if child not in parent:
                    parent[child] = node
                    following.append(child)
        frontier = following
    return component
