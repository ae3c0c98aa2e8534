"""The Python layer's layout rules, checked on the source: no module over 700 lines and no import
circle among evstwin's modules, imports inside functions and under TYPE_CHECKING included.

Circles are looked for twice. Between modules: A imports B imports A. Between *components*: a
package whose ``__init__`` imports its own submodules (a facade: ``psf``, ``targets``,
``validation``, ``plots``...) is one component, since importing any of its modules runs that
``__init__`` and so imports all of it; a package whose ``__init__`` imports nothing of its own
(``sky``) is not, and each of its modules is a component by itself."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "python" / "evstwin"
MAX_LINES = 700
OVER_THE_LIMIT: set[str] = set()
"""Modules allowed over MAX_LINES (none)."""


def _modules(root: Path = PACKAGE) -> dict[str, tuple[Path, bool]]:
    """{dotted name: (path, is a package)} of every module under ``root``."""
    out: dict[str, tuple[Path, bool]] = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return out


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """{module: the evstwin modules it imports anywhere in its source}. An evstwin import that
    names no module (a relative import gone stale after a move) raises AssertionError."""
    modules = _modules(root)
    known = set(modules) | {f"{root.name}._core"}  # the compiled extension
    graph: dict[str, set[str]] = {name: set() for name in known}
    for name, (path, is_package) in modules.items():
        package = name if is_package else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                # ``from pkg import sub`` imports the module pkg.sub; ``from mod import name`` mod
                targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in known else source for a in node.names]
            for target in targets:
                if target.split(".")[0] != root.name:
                    continue
                assert target in known, f"{path}: line {node.lineno} imports {target}, which does not exist"
                if target != name:
                    graph[name].add(target)
    return graph


def _facades(graph: dict[str, set[str]], root: Path = PACKAGE) -> set[str]:
    """The packages whose __init__ imports one of their own submodules."""
    packages = {name for name, (_, is_package) in _modules(root).items() if is_package and "." in name}
    return {p for p in packages if any(d.startswith(p + ".") for d in graph[p])}


def component_graph(graph: dict[str, set[str]], facades: set[str]) -> dict[str, set[str]]:
    """The graph with each facade package and its submodules merged into one node."""
    def node(module: str) -> str:
        owners = [p for p in facades if module == p or module.startswith(p + ".")]
        return min(owners, key=len) if owners else module

    out: dict[str, set[str]] = {}
    for module, deps in graph.items():
        out.setdefault(node(module), set()).update(node(d) for d in deps)
    for name, deps in out.items():
        deps.discard(name)
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_module_is_over_700_lines() -> None:
    long = {str(p.relative_to(PACKAGE)): n for p in PACKAGE.rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert set(long) <= OVER_THE_LIMIT, f"modules over {MAX_LINES} lines: {long}"


def test_no_import_circle_between_modules() -> None:
    assert cycles(import_graph()) == []


def test_no_import_circle_between_components() -> None:
    graph = import_graph()
    facades = _facades(graph)
    assert {"evstwin.psf", "evstwin.targets", "evstwin.validation", "evstwin.plots"} <= facades
    assert "evstwin.sky" not in facades  # its modules are imported by name, each on its own
    assert cycles(component_graph(graph, facades)) == []


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "evstwin"
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


def test_the_checker_finds_a_late_import_circle_and_a_facade_circle(tmp_path: Path) -> None:
    root = _tree(tmp_path, {
        "__init__.py": "",
        "a.py": "from .b import x\n",
        "b.py": "def f():\n    from . import a\n",
        "pkg/__init__.py": "from .inner import y\n",
        "pkg/inner.py": "from ..c import z\n",
        "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .pkg.other import w\n",
        "pkg/other.py": "",
    })
    graph = import_graph(root)
    assert cycles(graph) == [["evstwin.a", "evstwin.b"]]  # a late import closes it
    # c imports only pkg.other, but importing it runs pkg/__init__, which imports inner -> c
    assert cycles(component_graph(graph, _facades(graph, root))) == [["evstwin.a", "evstwin.b"],
                                                                     ["evstwin.c", "evstwin.pkg"]]


def test_the_checker_refuses_an_import_of_a_module_that_is_gone(tmp_path: Path) -> None:
    root = _tree(tmp_path, {"__init__.py": "", "pkg/__init__.py": "", "pkg/m.py": "def f():\n    from .sensor import S\n"})
    with pytest.raises(AssertionError, match=r"imports evstwin.pkg.sensor, which does not exist"):
        import_graph(root)
