"""The package's import graph (docs/architecture.md §1): no module imports, directly or through others, a module
that imports it back - at the top or inside a function - and ``tpnet_gpu/`` keeps its modules grouped by job.
Oracle: the ``import`` statements of the sources themselves (``ast``), mapped onto the installed names the way
``setup.py`` maps the four source roots."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = {"tpnet_gpu": "tpnet_gpu", "tpnet_gpu.kernels": "kernels", "tpnet_gpu.net": "net", "tpnet_gpu.bench": "bench"}
TOP_LEVEL_MODULES = 12  # issue 38: the package grouped by job


def _modules() -> dict[str, Path]:
    found = {}
    for package, folder in SOURCES.items():
        for path in (ROOT / folder).rglob("*.py"):
            parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join([package, *parts])] = path
    return found


def _graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules it imports (a name imported from a package counts as that package's module when it
    is one, else as the package)."""
    def owner(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in modules.items():
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                edges |= {owner(alias.name) for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                edges |= {owner(f"{node.module}.{a.name}") if f"{node.module}.{a.name}" in modules
                          else owner(node.module) for a in node.names}
        graph[name] = {e for e in edges if e is not None and e != name}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan)."""
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circles():
    graph = _graph(_modules())
    assert len(graph) > 150 and graph["tpnet_gpu.pipeline"]  # the scan found the package and its imports
    assert _circles(graph) == []


def test_the_circle_finder_finds_one():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_package_is_grouped_by_job():
    top = sorted(p.name for p in (ROOT / "tpnet_gpu").glob("*.py"))
    assert len(top) <= TOP_LEVEL_MODULES, top
