"""The course structure the lecturer's guide (docs/course.md) relies on, for every notebook and solution (jupytext
percent files).  Executing them (small sizes, outside the checkout) and checking the built pages offline in a
browser: tests/test_course.py."""

import ast
import re
from pathlib import Path

import pytest

NOTEBOOK_DIR = Path(__file__).parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.py"))
SOLUTIONS = sorted((NOTEBOOK_DIR / "solutions").glob("[0-9][0-9]_*.py"))


def _read(path):
    jupytext = pytest.importorskip("jupytext")
    return jupytext.read(path)


def _imports(source: str) -> list[tuple[str, list[str]]]:
    """(module, imported names) of every import statement in a cell's Python source."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.append((node.module, [a.name for a in node.names]))
        elif isinstance(node, ast.Import):
            out.extend((a.name, []) for a in node.names)
    return out


def test_the_course_has_at_least_eight_notebooks_each_with_a_solution():
    assert len(NOTEBOOKS) >= 8
    numbers = [p.name[:2] for p in NOTEBOOKS]
    assert numbers == [f"{k:02d}" for k in range(1, len(NOTEBOOKS) + 1)], "numbered in course order, no gaps"
    assert [p.name[:2] for p in SOLUTIONS] == numbers, "one solutions file per notebook"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_structure(path):
    nb = _read(path)
    markdown = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert nb.cells[0].source.lstrip().startswith(f"# {path.name[:2]} "), "opens with its numbered title"
    for heading in ("**Learning goals.**", "**Prerequisites.**", "**Estimated time.**"):
        assert heading in nb.cells[0].source, heading
    assert "$$" in markdown, "equations written out in LaTeX"
    assert re.search(r"^assert ", code, re.M), "equations checked numerically"
    assert re.search(r"interactive_figure\(|residual_panel\(|scene_view\(", code), "an interactive cell"
    exercises = markdown.split("## Exercises")[-1]
    assert "## Exercises" in markdown and len(re.findall(r"^\d+\. ", exercises, re.M)) >= 3, "three exercises"
    params = [c for c in nb.cells if "parameters" in c.metadata.get("tags", [])]
    assert len(params) == 1 and "PUSHBROOM_NB_SMALL" in params[0].source, "one parameter cell with a small mode"


ALL = NOTEBOOKS + SOLUTIONS


@pytest.mark.parametrize("path", ALL, ids=[f"{p.parent.name}/{p.stem}" for p in ALL])
def test_imports_only_the_public_api(path):
    nb = _read(path)
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for module, names in _imports(cell.source):
            if module.split(".")[0] != "explorer":
                continue
            assert not any(part.startswith("_") for part in module.split(".")), f"private module {module}"
            assert not any(n.startswith("_") for n in names), f"private name from {module}: {names}"


@pytest.mark.parametrize("path", ALL, ids=[f"{p.parent.name}/{p.stem}" for p in ALL])
def test_reads_files_only_from_the_installed_package_or_a_parameter(path):
    """Copied anywhere, a notebook still runs: no path into the checkout (tests/data, benchmarks/, the parent of the
    working directory, sys.path tricks); data comes from ``explorer.assets`` through importlib.resources."""
    nb = _read(path)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    for pattern in (r"tests/data|[\"']tests[\"']", r"benchmarks", r"Path\.cwd\(\)", r"\.\./", r"sys\.path",
                    r"__file__", r"/work/"):
        assert not re.search(pattern, code), f"{path.name} reaches outside the package: {pattern}"


@pytest.mark.parametrize("path", SOLUTIONS, ids=[p.stem for p in SOLUTIONS])
def test_solution_checks_every_exercise(path):
    nb = _read(path)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    markdown = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    n_exercises = len(re.findall(r"^## Exercise \d+", markdown, re.M))
    assert n_exercises >= 3 and len(re.findall(r"^\s*assert ", code, re.M)) >= n_exercises


def test_the_course_covers_the_3d_view_and_a_widget():
    sources = {p.stem: "\n".join(c.source for c in _read(p).cells) for p in NOTEBOOKS}
    assert any("scene_view(" in s for s in sources.values())
    assert any("residual_panel(" in s for s in sources.values())
