"""No import cycles in the package, also not through imports inside functions: a cycle hidden in a function still
ties two modules into one (neither can be understood, tested or moved alone) and breaks the day someone lifts the
import to the top. Read from the source with `ast` (tests/import_graph.py); a cycle is printed module by module.

KNOWN lists the cycles not broken yet (issue 34 item 8), each by its smallest module: a new cycle fails, and so does
a known one that is gone (delete its line: the list only shrinks).
"""

from __future__ import annotations

from tests import import_graph

KNOWN = {
    # Robot.load of a file without a record infers one, and inference measures candidate cameras with a Robot: a
    # recursion at run time, broken only by handing infer_record the loader (12 callers) or one module for both.
    "bodyschema.datagen.body.infer",
}


def test_the_package_has_no_import_cycle():
    found = import_graph.imports(import_graph.package_modules())
    cycles = import_graph.cycles(import_graph.graph(found))
    where = {(i.source, i.target): f"{i.source}:{i.line}{' (in a function)' if i.in_function else ''}" for i in found}
    new = [c for c in cycles if c[0] not in KNOWN]
    shown = ["\n  ".join(where[(a, b)] + f" imports {b}" for a, b in zip(cycle, cycle[1:])) for cycle in new]
    assert not new, f"{len(new)} new import cycle(s); move the shared piece into the lower module:\n  " + \
        "\n\n  ".join(shown)
    gone = KNOWN - {c[0] for c in cycles}
    assert not gone, f"cycles broken: delete {sorted(gone)} from KNOWN"


def test_a_cycle_is_found_inside_functions():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_graph.cycles(edges) == [["a", "b", "c", "a"]]
    assert import_graph.cycles({"a": {"b"}, "b": set()}) == []
