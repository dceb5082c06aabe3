"""The package's layering, checked on the source: one import graph of uq/*.py, built with ``ast``.

Layers, bottom to top: models and library (everything not named below) -> reports
(``_report``, ``_surface_report``) -> command line (``cli``, ``_cmd_*``). Drivers that run whole
pipelines (``_batch``, ``_bench``, ``_calibrate``) sit beside the command line. A module may import
from its own layer or below, never above, and the uq modules import each other without cycles.
Both top-level and function-level imports count: a cycle through a function-level import is still
a cycle (the modules cannot be split or loaded on their own), only a later one.

The exceptions of today are listed below, each with its reason; a listed exception that is no longer
needed fails the test too, so the lists only shrink.
"""

from __future__ import annotations

import ast
from pathlib import Path

UQ = Path(__file__).resolve().parents[1] / "uq"

#: Modules that library code must not import: the command line and the HTML reports.
REPORTS = {"_report", "_surface_report"}
DRIVERS = {"_batch", "_bench", "_calibrate"}


def is_cli(name: str) -> bool:
    return name == "cli" or name.startswith("_cmd_")


def is_upper(name: str) -> bool:
    return is_cli(name) or name in REPORTS


def is_library(name: str) -> bool:
    return not (is_upper(name) or name in DRIVERS)


#: Library modules that still define their command (``configure_NAME``/``command_NAME`` for
#: uq/cli.py) and so import the command line's helpers or a report: (module, imported) -> reason.
#: Each goes when its command moves to a ``_cmd_NAME`` module.
KNOWN_ARGPARSE: dict = {}

#: Imports that close a cycle, allowed for now: (module, imported) -> reason. The cycle check
#: runs on the graph without them.
KNOWN_CYCLE_EDGES: dict = {}


def _module_names() -> set[str]:
    return {"uq" if p.stem == "__init__" else p.stem for p in UQ.glob("*.py")}


def _targets(node: ast.AST, modules: set[str]) -> list[str]:
    """The uq modules an import statement loads (``from . import x``: x when it is a module)."""
    out = []
    if isinstance(node, ast.Import):
        for a in node.names:
            parts = a.name.split(".")
            if parts[0] == "uq":
                out.append(parts[1] if len(parts) > 1 else "uq")
    elif isinstance(node, ast.ImportFrom):
        if node.level == 0:
            parts = (node.module or "").split(".")
            if parts[0] != "uq":
                return out
            rest = parts[1:]
        elif node.level == 1:
            rest = (node.module or "").split(".") if node.module else []
        else:  # beyond the package: not a uq module
            return out
        if rest:
            out.append(rest[0])
        else:  # from . import a, b / from uq import a, b
            out += [a.name if a.name in modules else "uq" for a in node.names]
    return [m for m in out if m in modules]


def import_graph() -> dict[tuple[str, str], list[str]]:
    """(importer, imported) -> where: 'file:line (top level)' or 'file:line (in function f)'."""
    modules = _module_names()
    edges: dict[tuple[str, str], list[str]] = {}
    for path in sorted(UQ.glob("*.py")):
        src = "uq" if path.stem == "__init__" else path.stem
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))

        def visit(node, scope, path=path, src=src):
            for child in ast.iter_child_nodes(node):
                inner = child.name if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef) else scope
                for dst in _targets(child, modules):
                    if dst != src:
                        where = "top level" if scope is None else f"in function {scope}"
                        edges.setdefault((src, dst), []).append(f"uq/{path.name}:{child.lineno} ({where})")
                visit(child, inner)

        visit(tree, None)
    return edges


def _cycles(edges) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
        graph.setdefault(b, set())
    index, low, stack, on, out = {}, {}, [], set(), []

    def strong(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_graph_sees_the_imports_it_must():
    edges = import_graph()
    assert ("_surface_report", "_surface") in edges  # top-level relative import
    assert ("_report", "_surface") in edges  # function-level import (command_report --surface)
    assert ("_batch", "uq") in edges  # from . import __version__
    assert ("_diagnose", "_diagnose_models") in edges  # from . import _diagnose_models as M


def test_no_import_cycles():
    edges = {e: w for e, w in import_graph().items() if e not in KNOWN_CYCLE_EDGES}
    cycles = _cycles(edges)
    detail = [
        " -> ".join(c) + ": " + "; ".join(f"{a} imports {b} at {', '.join(w)}" for (a, b), w in edges.items()
                                          if a in c and b in c)
        for c in cycles
    ]
    assert not cycles, "import cycles among uq modules:\n" + "\n".join(detail)


def test_library_modules_do_not_import_the_cli_or_the_reports():
    bad = {
        (a, b): w for (a, b), w in import_graph().items()
        if is_library(a) and is_upper(b) and (a, b) not in KNOWN_ARGPARSE
    }
    assert not bad, "library modules importing the command line or a report:\n" + "\n".join(
        f"{a} -> {b}: {', '.join(w)}" for (a, b), w in sorted(bad.items()))


def test_known_exceptions_are_still_needed():
    """A listed exception that the code no longer needs must leave the list (it only shrinks)."""
    edges = import_graph()
    stale = [e for e in {**KNOWN_ARGPARSE, **KNOWN_CYCLE_EDGES} if e not in edges]
    assert not stale, f"no longer imported, remove from the lists in tests/test_layers.py: {stale}"
    assert all(is_library(a) and is_upper(b) for a, b in KNOWN_ARGPARSE)


def test_package_imports_no_submodule_on_import():
    """uq/__init__.py loads its public names lazily (PEP 562): ``import uq`` stays cheap."""
    assert not [e for e in import_graph() if e[0] == "uq"]
