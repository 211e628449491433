"""The package's modules import one way: no import circle, lazy (function-level) imports included.

Every ``import`` statement of every module under ``omnicam/`` is an edge, wherever it stands in
the file; a package edge points at its ``__init__``. The graph must have no strongly connected
component with more than one module (the layers of docs/architecture.md, "Layout").
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


def test_the_camera_sits_at_the_bottom_of_the_house():
    """The model imports only the layers under it; the routes, views and formats import it."""
    graph = import_graph()
    under = {
        "omnicam._typing",
        "omnicam._validate",
        "omnicam.gauge",
        "omnicam.mirror",
        "omnicam.asphere",
        "omnicam.raytrace",
    }
    assert graph["omnicam.camera"] <= under, graph["omnicam.camera"] - under
    for low in under:
        assert "omnicam.camera" not in graph[low], low
    for above in (
        "omnicam.views.api",
        "omnicam.calibration",
        "omnicam.chessboard.calibrate",
        "omnicam.formats.calibration_file",
    ):
        assert "omnicam.camera" in graph[above], above


def test_no_camera_class_is_passed_down_the_layers():
    """No ``camera_cls``, ``make_camera`` or ``CameraLike``: the layers import the camera."""
    for path in ROOT.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        for name in ("camera_cls", "make_camera", "CameraLike", "CameraT"):
            assert name not in text, (path.name, name)


#: Lines a module of the library may have: one concept a module, reviewable in a sitting.
MAX_MODULE_LINES = 800
#: Parameters a function may take; a public entry point may take more, its options keyword-only.
MAX_PARAMETERS = 10


def _functions(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def test_no_module_of_the_library_is_over_800_lines():
    long = {
        str(p.relative_to(ROOT)): n
        for p in ROOT.rglob("*.py")
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert not long, long


def test_functions_take_at_most_10_parameters_but_public_entry_points_by_keyword():
    """A private function (or any of a private module) takes at most 10 parameters; a public
    one may take more only as keyword-only options after at most 10 positional ones."""
    bad = []
    for path in ROOT.rglob("*.py"):
        private_module = any(
            part.startswith("_") and part != "__init__.py" for part in path.relative_to(ROOT).parts
        )
        for f in _functions(ast.parse(path.read_text(encoding="utf-8"))):
            a = f.args
            positional = [x.arg for x in a.posonlyargs + a.args if x.arg not in ("self", "cls")]
            total = len(positional) + len(a.kwonlyargs)
            if total <= MAX_PARAMETERS:
                continue
            public = not f.name.startswith("_") and not private_module
            if not public or len(positional) > MAX_PARAMETERS:
                bad.append(f"{path.relative_to(ROOT)}:{f.lineno} {f.name} ({total})")
    assert not bad, bad
