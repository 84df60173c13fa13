"""The package's import graph: no circle, one direction between layers (``docs/dev/architecture.md``).

Imports are read from the source with :mod:`ast`, function-level ones included (a lazy import is still
an edge: it may not close a circle either), and so are the imports made for type checking only
(``if TYPE_CHECKING:``): two modules that name each other's types are one concept split in two, and
the circle shows the moment a type checker or a ``typing.get_type_hints`` call follows it.  Discovery by
``importlib`` (the method registry) is not an import statement.
"""

from __future__ import annotations

import ast
import sys
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "explorer"

#: Lowest first; a module may import only from its own layer or lower ones (docs/dev/architecture.md).
LAYERS = [
    ["explorer.errors", "explorer._numba", "explorer._threads", "explorer._lazy", "explorer._resources",
     "explorer._log", "explorer.io_atomic", "explorer.io_input", "explorer.memory", "explorer.float_text"],
    ["explorer.geometry"],
    ["explorer.sensor", "explorer.scene", "explorer.scene_checks"],
    ["explorer.presets", "explorer.points", "explorer.terrain_io", "explorer.rpc"],
    ["explorer.real", "explorer.methods", "explorer.stereo"],
    ["explorer.evaluate", "explorer.bench_defaults", "explorer.bench", "explorer.ortho", "explorer.warmup",
     "explorer.kernel_cache", "explorer.refine"],
    ["explorer.panels", "explorer.scene3d"],
    ["explorer.app", "explorer.notebook", "explorer.commands", "explorer.cli", "explorer.__main__", "explorer"],
]
MODEL_LAYERS = 6  # layers below this never import the GUI libraries
GUI_LIBRARIES = ("viser", "plotly", "IPython", "ipywidgets")


@cache
def module_files() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the package."""
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST, type_checking: bool) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement at any depth; those inside ``if TYPE_CHECKING:`` only with ``type_checking``."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if not type_checking and isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


@cache
def imported_names(name: str, path: Path, type_checking: bool = True) -> list[tuple[str, int]]:
    """(absolute dotted name, line) of every import of a module; ``type_checking=False`` leaves out those made
    for type checking only."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in _import_nodes(ast.parse(path.read_text(), str(path)), type_checking):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
            continue
        if node.level:
            base = package.split(".")[: len(package.split(".")) - node.level + 1]
            module = ".".join(base + ([node.module] if node.module else []))
        else:
            module = node.module or ""
        out += [(f"{module}.{a.name}", node.lineno) for a in node.names]
    return out


@cache
def import_graph(type_checking: bool = True) -> dict[str, dict[str, int]]:
    """Module -> {imported package module: line}; ``from a import b`` counts as ``a.b`` when that is a module.
    ``type_checking=False``: without the imports made for type checking only."""
    files = module_files()

    def resolve(dotted: str) -> str | None:
        while dotted and dotted not in files:
            dotted = dotted.rpartition(".")[0]
        return dotted or None

    graph: dict[str, dict[str, int]] = {}
    for name, path in files.items():
        edges: dict[str, int] = {}
        for dotted, line in imported_names(name, path, type_checking):
            target = resolve(dotted)
            if target is not None and target != name:
                edges.setdefault(target, line)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def strongconnect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in graph:
            if v not in index:
                strongconnect(v)
    finally:
        sys.setrecursionlimit(limit)
    return found


def layer_of(module: str) -> int | None:
    best = None
    for k, prefixes in enumerate(LAYERS):
        for p in prefixes:
            if module == p or module.startswith(p + "."):
                if best is None or len(p) > best[1]:
                    best = (k, len(p))
    return None if best is None else best[0]


def test_the_cycle_finder_finds_a_planted_circle():
    graph = {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1}, "d": {"a": 1}}
    assert cycles(graph) == [["a", "b", "c"]]
    graph["c"] = {}
    assert cycles(graph) == []


def test_function_level_relative_and_type_checking_imports_are_edges(tmp_path):
    src = (
        "import typing\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from explorer.app import gui\n"
        "if typing.TYPE_CHECKING:\n    import explorer.panels\nelse:\n    import explorer.bench\n"
        "def f():\n    from explorer.scene import Scene\n    from . import points\n"
    )
    path = tmp_path / "mod.py"
    path.write_text(src)
    names = [n for n, _ in imported_names("explorer.real.mod", path)]
    assert "explorer.scene.Scene" in names and "explorer.real.points" in names
    assert {"explorer.app.gui", "explorer.panels", "explorer.bench"} <= set(names)
    runtime = [n for n, _ in imported_names("explorer.real.mod", path, type_checking=False)]
    assert "explorer.bench" in runtime and not any(n.startswith(("explorer.app", "explorer.panels")) for n in runtime)


def test_a_circle_closed_only_by_a_type_checking_import_is_found(tmp_path):
    """The shape of the former rpc/model <-> rpc/inverse circle: a function-level import one way, a
    type-checking one back."""
    (tmp_path / "model.py").write_text("def on_dem():\n    from explorer.rpc.inverse import RPCInverse\n")
    (tmp_path / "inverse.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from explorer.rpc.model import Model\n")
    graph = {}
    for name in ("model", "inverse"):
        dotted = [n for n, _ in imported_names(f"explorer.rpc.{name}", tmp_path / f"{name}.py")]
        graph[f"explorer.rpc.{name}"] = {n.rpartition(".")[0]: 1 for n in dotted if n.startswith("explorer.rpc.")}
    assert cycles(graph) == [["explorer.rpc.inverse", "explorer.rpc.model"]]


def test_no_import_circle_among_explorer_modules():
    graph = import_graph()
    assert len(graph) > 50  # the whole package was read
    found = cycles(graph)
    detail = [[f"{m} -> {t} (line {graph[m][t]})" for m in comp for t in graph[m] if t in comp] for comp in found]
    assert found == [], f"import circles: {detail}"
    # the explorer's controls reach the app through its public methods only (issue 23)
    assert "explorer.app.gui" not in graph["explorer.app.controls"]


def test_imports_go_one_way_between_layers():
    """Runtime imports: an annotation may name a type of a higher layer (``geometry.kernels`` packs a ``Scene``)
    as long as no circle closes (checked above with the type-checking imports counted)."""
    graph = import_graph(type_checking=False)
    unlayered = sorted(m for m in graph if layer_of(m) is None)
    assert unlayered == [], f"modules not placed in a layer (tests/test_import_graph.py LAYERS): {unlayered}"
    upward = [
        f"{m} (layer {layer_of(m)}) imports {t} (layer {layer_of(t)}) at line {line}"
        for m, edges in graph.items()
        for t, line in edges.items()
        if layer_of(t) > layer_of(m)
    ]
    assert upward == []


def test_the_scene_imports_nothing_from_real_images():
    graph = import_graph()
    assert not [t for t in graph["explorer.scene"] if t.startswith("explorer.real")]


@pytest.mark.parametrize("library", GUI_LIBRARIES)
def test_the_model_layers_never_import_gui_libraries(library):
    files = module_files()
    offenders = [
        f"{name}:{line}"
        for name, path in files.items()
        if (layer_of(name) or 0) < MODEL_LAYERS
        for dotted, line in imported_names(name, path)
        if dotted == library or dotted.startswith(library + ".")
    ]
    assert offenders == []


#: Private modules of the package root that every subpackage may use (the package's own infrastructure).
SHARED_PRIVATE = {"explorer._numba", "explorer._threads", "explorer._lazy", "explorer._resources", "explorer._log"}


def _package_of(module: str) -> str:
    """``explorer.geometry.kernels.exact`` -> ``explorer.geometry``; top-level modules are their own package."""
    parts = module.split(".")
    return ".".join(parts[:2])


def test_private_names_stay_in_their_package():
    """``from explorer.<pkg>... import _name`` (or of a ``_module``) only from inside ``explorer.<pkg>``."""
    files = module_files()
    offenders = []
    for name, path in files.items():
        for dotted, line in imported_names(name, path):
            if not dotted.startswith("explorer."):
                continue
            parts = dotted.split(".")
            private = [k for k, p in enumerate(parts) if p.startswith("_") and not p.startswith("__")]
            if not private:
                continue
            owner = ".".join(parts[: max(private[0], 2)])  # the package (or root module) the name belongs to
            if owner in SHARED_PRIVATE:
                continue
            if _package_of(name) != _package_of(owner):
                offenders.append(f"{name}:{line} imports {dotted}")
    assert offenders == []


#: Modules the export's sweep worker (explorer.app.sweep_pool) must not import: the GUI's modules and libraries,
#: and the heavy libraries the worker never calls (scipy.optimize: resection and the DIMAP calibration, which
#: run in the command only; torch: the networks train without it).  Each costs the worker's process CPU time
#: before its first job (issue 24: the export's 5 s).
NOT_IN_THE_SWEEP_WORKER = ("explorer.app.gui", "explorer.app.controls", "explorer.app.views", "explorer.app.server",
                           "explorer.app.jobs", "viser", "plotly", "scipy.optimize", "torch")


def test_the_sweep_workers_imports_leave_out_the_gui_and_what_it_never_calls():
    """A fresh interpreter imports what the worker imports before its first job (its module, the model, the
    method registry, the modules of a real sensor's pickle): the modules present afterwards (``sys.modules``,
    the interpreter's own record) include none of :data:`NOT_IN_THE_SWEEP_WORKER`."""
    import json
    import subprocess

    code = ("import json, sys\n"
            "import explorer.app.sweep_pool\n"
            "from explorer.app.model import SWEEP_PURPOSE, ExplorerModel\n"
            "from explorer.methods import registry\n"
            "registry()\n"
            "import explorer.real, explorer.real.linescan, explorer.rpc.model\n"
            "print(json.dumps(sorted(sys.modules)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT,
                         check=True)
    modules = set(json.loads(out.stdout.splitlines()[-1]))
    assert "explorer.app.model" in modules and "explorer.methods.bpnn" in modules  # the imports did run
    assert sorted(modules & set(NOT_IN_THE_SWEEP_WORKER)) == []


def test_the_app_packages_names_are_its_submodules_objects():
    """``explorer.app`` imports its names on first access (so that the worker's ``explorer.app.model`` comes
    without the GUI): every name of ``__all__`` is the very object of the submodule that defines it."""
    import importlib

    import explorer.app as app

    for name in app.__all__:
        source = importlib.import_module(app._SOURCES[name])
        assert getattr(app, name) is getattr(source, name), name
    assert set(app.__all__) == set(app._SOURCES) and set(app.__all__) <= set(dir(app))
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        app.no_such_name  # noqa: B018
    from explorer.app import export  # a submodule is still imported by name

    assert export.__name__ == "explorer.app.export"
