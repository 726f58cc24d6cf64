"""The import graph of occgp's own modules, and its circles.

Every ``import`` and ``from ... import`` in a module counts as an edge, wherever it
stands: at the top or inside a function (a circle of files is one whichever line
closes it); only imports under ``if TYPE_CHECKING:``, which never run, are left out. ``importlib.import_module("occgp....")`` with a
literal name counts too, so that an import hidden behind it still shows. Nodes are
files: ``occgp/x.py`` is ``occgp.x``, ``occgp/pkg/__init__.py`` is ``occgp.pkg``;
``from .pkg import name`` goes to the module ``pkg.name`` when that is a file, to
``pkg`` otherwise.

Run ``python tools/import_graph.py`` for the circles (strongly connected components
of more than one module, or a module importing itself), one per line, and the count;
``--edges`` prints every edge as well. The exit status is 1 when a circle exists.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "occgp"


def module_files(root: Path = ROOT, package: str = PACKAGE) -> dict[str, Path]:
    """Map each module name of ``package`` to its source file (a compiled module, known
    by its ``.pyi`` stub or its shared library, to that file: it imports nothing of
    occgp)."""
    files = {}
    paths = sorted((root / package).rglob("*.py"))
    paths += sorted(p for p in (root / package).rglob("*.pyi")
                    if not p.with_suffix(".py").exists())
    paths += sorted(p for p in (root / package).rglob("*.so")
                    if not p.with_name(p.name.split(".")[0] + ".pyi").exists())
    for path in paths:
        parts = path.relative_to(root).parts
        parts = parts[:-1] + (parts[-1].split(".")[0],)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        files[".".join(parts)] = path
    return files


def _target(name: str, modules: set[str]) -> str | None:
    """The deepest module of ``modules`` that ``name`` names or lies in."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in modules:
            return candidate
    return None


def _base(module: str, level: int, is_package: bool) -> str:
    parts = module.split(".")
    keep = len(parts) - level + (1 if is_package else 0)
    return ".".join(parts[:keep])


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _runtime_nodes(tree: ast.AST):
    """Every node of `tree` but those under ``if TYPE_CHECKING:`` (never run)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            todo.extend(node.orelse)
            continue
        todo.extend(ast.iter_child_nodes(node))


def imports_of(module: str, path: Path, modules: set[str]) -> dict[str, int]:
    """The occgp modules ``module`` imports, each with the line of its first import."""
    is_package = path.name == "__init__.py"
    found: dict[str, int] = {}
    if path.suffix != ".py":
        return found

    def add(name: str | None, line: int) -> None:
        if name and name != module:
            found.setdefault(name, line)

    for node in _runtime_nodes(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(_target(alias.name, modules), node.lineno)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or "" if not node.level else \
                ".".join(filter(None, [_base(module, node.level, is_package), node.module]))
            if not base.startswith(PACKAGE):
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                add(sub if sub in modules else _target(base, modules), node.lineno)
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else \
                func.id if isinstance(func, ast.Name) else None
            if name in ("import_module", "__import__") and node.args and \
                    isinstance(node.args[0], ast.Constant) and \
                    isinstance(node.args[0].value, str):
                add(_target(node.args[0].value, modules), node.lineno)
    return found


def import_graph(root: Path = ROOT, package: str = PACKAGE) -> dict[str, dict[str, int]]:
    """``{module: {imported module: line}}`` over every module of ``package``."""
    files = module_files(root, package)
    names = set(files)
    return {m: imports_of(m, p, names) for m, p in files.items()}


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's algorithm,
    iterative), each sorted, largest first."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(graph[start]))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in graph:
                    continue
                if nxt not in index:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(graph[nxt])))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1 or node in graph[node]:
                        found.append(sorted(component))
    return sorted(found, key=lambda c: (-len(c), c))


def cycle_edges(graph: dict[str, dict[str, int]], component: list[str]) -> list[str]:
    """The edges inside one component, as ``a:line -> b``."""
    members = set(component)
    return [f"{a}:{line} -> {b}" for a in component
            for b, line in sorted(graph[a].items()) if b in members]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--edges", action="store_true", help="print every edge too")
    args = parser.parse_args(argv)
    graph = import_graph()
    if args.edges:
        for a, targets in graph.items():
            for b, line in sorted(targets.items()):
                print(f"{a}:{line} -> {b}")
    found = circles(graph)
    n_edges = sum(len(t) for t in graph.values())
    print(f"{len(graph)} modules, {n_edges} edges, {len(found)} import circles")
    for component in found:
        print(f"circle of {len(component)}: {', '.join(component)}")
        for edge in cycle_edges(graph, component):
            print(f"    {edge}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
