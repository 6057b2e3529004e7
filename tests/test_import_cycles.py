"""No import cycles in the package, also not through imports inside functions: a cycle hidden in a function still
ties two modules into one (neither can be understood, tested or moved alone) and breaks the day someone lifts the
import to the top. Read from the source with `ast` (tests/import_graph.py); a cycle is printed module by module.
"""

from __future__ import annotations

from tests import import_graph


def test_the_package_has_no_import_cycle():
    found = import_graph.imports(import_graph.package_modules())
    cycles = import_graph.cycles(import_graph.graph(found))
    where = {(i.source, i.target): f"{i.source}:{i.line}{' (in a function)' if i.in_function else ''}" for i in found}
    shown = ["\n  ".join(where[(a, b)] + f" imports {b}" for a, b in zip(cycle, cycle[1:])) for cycle in cycles]
    assert not cycles, f"{len(cycles)} import cycle(s); move the shared piece into the lower module:\n  " + \
        "\n\n  ".join(shown)


def test_a_cycle_is_found_inside_functions():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_graph.cycles(edges) == [["a", "b", "c", "a"]]
    assert import_graph.cycles({"a": {"b"}, "b": set()}) == []
