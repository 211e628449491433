"""The package's modules import one way: no import circle, lazy (function-level) imports included.

Every ``import`` statement of every module under ``omnicam/`` is an edge, wherever it stands in
the file; a package edge points at its ``__init__``. The graph must have no strongly connected
component with more than one module (the layers of the README's Layout section).
"""

import ast
from pathlib import Path

import omnicam

ROOT = Path(omnicam.__file__).parent


def module_name(path):
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph():
    modules = {module_name(p): p for p in ROOT.rglob("*.py")}
    graph = {m: set() for m in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                # ``from pkg import submodule`` imports the submodule; ``from mod import name``
                # the module that defines the name
                targets = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                    for a in node.names
                ]
            for t in targets:
                while t and t not in modules:
                    t = t.rpartition(".")[0]
                if t and t != name and t.startswith("omnicam"):
                    graph[name].add(t)
    return graph


def import_circles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
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
            visit(v)
    return out


def test_package_has_no_import_circle():
    assert import_circles(import_graph()) == []


def test_the_circle_finder_finds_a_circle():
    assert import_circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_low_layers_import_nothing_of_the_camera():
    graph = import_graph()
    for low in (
        "omnicam._validate",
        "omnicam.gauge",
        "omnicam.mirror",
        "omnicam.asphere",
        "omnicam.formats.omnicam_files",
        "omnicam.raytrace",
        "omnicam.views",
        "omnicam._kernels",
    ):
        assert "omnicam.camera" not in graph[low], low
