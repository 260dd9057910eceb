"""Print the import graph between avrisk's subpackages or modules, and its cycles.

Command (from the repository root)::

    python scripts/import_graph.py [PACKAGE_DIR] [--modules]

``PACKAGE_DIR`` defaults to this checkout's ``avrisk/``. The source is parsed
(:mod:`ast`), never imported, so any checkout can be inspected. A node is a
subpackage (``avrisk/sim/``) or a top-level module (``avrisk/registry.py``);
an edge ``a -> b  (n)`` says that ``n`` import statements in ``a`` name
``avrisk.b``, wherever they stand (top level, inside a function, under
``TYPE_CHECKING``). With ``--modules`` a node is a module (``avrisk.sim.road``;
a package's ``__init__.py`` is the package, ``avrisk.sim``) and an import
names the module it imports from, or the submodule it imports
(:func:`module_edges`). Cycles are listed one per strongly connected
component, as one closed path through it; ``tests/test_architecture.py``
asserts there are none at either level.
"""

from __future__ import annotations

import argparse
import ast
from collections import Counter
from collections.abc import Iterator, Mapping
from pathlib import Path

__all__ = [
    "cycles",
    "imported_subpackages",
    "module_edges",
    "strong_components",
    "subpackage_edges",
]

ROOT = "avrisk"


def imported_subpackages(path: Path) -> Iterator[str]:
    """The avrisk subpackage (or top-level module) of every import in a file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [node.module]
        for name in names:
            parts = name.split(".")
            if parts[0] == ROOT and len(parts) > 1:
                yield parts[1]


def subpackage_edges(package: Path) -> Counter[tuple[str, str]]:
    """``(importer, imported) -> number of import statements``, self-edges left out.

    Parameters
    ----------
    package : Path
        The ``avrisk/`` folder.
    """
    edges: Counter[tuple[str, str]] = Counter()
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        if rel.parts == ("__init__.py",):
            continue
        node = rel.parts[0].removesuffix(".py")
        edges.update((node, dst) for dst in imported_subpackages(path) if dst != node)
    return edges


def module_name(package: Path, path: Path) -> str:
    """The dotted name of the module at ``path`` (a package for ``__init__.py``)."""
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def module_edges(package: Path) -> Counter[tuple[str, str]]:
    """``(importer, imported) -> import statements`` between modules, no self-edges.

    ``from a.b import c`` names the module ``a.b.c`` where that is a module of
    the package, else ``a.b``; a name outside the package is left out.
    Importing a module runs its packages' ``__init__`` first: those implicit
    edges are not counted (every submodule would otherwise sit in a circle
    with a package that imports it).

    Parameters
    ----------
    package : Path
        The ``avrisk/`` folder.
    """
    files = {module_name(package, p): p for p in sorted(package.rglob("*.py"))}
    edges: Counter[tuple[str, str]] = Counter()
    for name, path in files.items():
        here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: from the importer's package upwards
                    up = here[: len(here) - node.level + 1]
                    base = ".".join([*up, *([node.module] if node.module else [])])
                targets = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in files else base
                    for a in node.names
                ]
            for target in targets:
                while target and target not in files:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    edges[(name, target)] += 1
    return edges


def _graph(edges: Mapping[tuple[str, str], int]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
        graph.setdefault(b, set())
    return graph


def strong_components(edges: Mapping[tuple[str, str], int]) -> list[list[str]]:
    """The strongly connected components of more than one node, sorted."""
    graph = _graph(edges)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def connect(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
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
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return sorted(components)


def cycles(edges: Mapping[tuple[str, str], int]) -> list[list[str]]:
    """One closed path ``[a, b, ..., a]`` per strongly connected component."""
    graph = _graph(edges)
    return [_closed_path(graph, set(c)) for c in strong_components(edges)]


def _closed_path(graph: dict[str, set[str]], component: set[str]) -> list[str]:
    """A cycle through the first node of a strongly connected component (BFS)."""
    start = min(component)
    parent: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & component):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(parent[path[-1]])
                    return [start, *reversed(path[:-1]), start]
                if w not in parent:
                    parent[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{sorted(component)} is not strongly connected")


def main() -> None:
    """Print the edges with their counts, then the cycles."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = Path(__file__).resolve().parents[1] / ROOT
    parser.add_argument("package", nargs="?", type=Path, default=default)
    parser.add_argument(
        "--modules", action="store_true", help="modules as nodes, not subpackages"
    )
    args = parser.parse_args()
    package = args.package.resolve()
    edges = module_edges(package) if args.modules else subpackage_edges(package)
    level = "module" if args.modules else "subpackage"
    nodes = {n for edge in edges for n in edge}
    print(f"{level} imports in {package}: {len(nodes)} nodes, {len(edges)} edges")
    print("(importer -> imported, statements):")
    for (a, b), n in sorted(edges.items()):
        print(f"  {a} -> {b}  ({n})")
    components = strong_components(edges)
    print(f"cycles: {len(components)}")
    for members, path in zip(components, cycles(edges), strict=True):
        inside = [f"{a} -> {b}" for a, b in sorted(edges) if {a, b} <= set(members)]
        print(f"  {' -> '.join(path)}  [component {{{', '.join(members)}}}: ", end="")
        print(", ".join(inside) + "]")


if __name__ == "__main__":
    main()
