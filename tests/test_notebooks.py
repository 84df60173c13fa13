"""Execute every course notebook and every worked solution (jupytext percent files) at its small CI size,
and check the course structure the lecturer's guide (docs/course.md) relies on."""

import ast
import os
import re
from pathlib import Path

import pytest

NOTEBOOK_DIR = Path(__file__).parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.py"))
SOLUTIONS = sorted((NOTEBOOK_DIR / "solutions").glob("[0-9][0-9]_*.py"))
VISER_EMBED = "__VISER_EMBED_DATA__"
WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"


def _read(path):
    jupytext = pytest.importorskip("jupytext")
    return jupytext.read(path)


def _execute(nb, path):
    nbclient = pytest.importorskip("nbclient")
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute(env={**os.environ, "PUSHBROOM_NB_SMALL": "1"})
    return nb


def _outputs(nb):
    for cell in nb.cells:
        yield from cell.get("outputs", [])


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


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path):
    nb = _execute(_read(path), path)
    source = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    html = [o["data"].get("text/html", "") for o in _outputs(nb) if "data" in o]
    if "scene_view(" in source:  # the inline 3D view: viser's static viewer with the scene embedded
        assert any(VISER_EMBED in h for h in html)
    if "interactive_figure(" in source or "residual_panel(" in source:  # a live widget plus its static copy
        widgets = [o for o in _outputs(nb) if WIDGET_VIEW in o.get("data", {})]
        assert widgets and all(".newPlot(" in o["data"]["text/html"] for o in widgets)


@pytest.mark.slow
@pytest.mark.parametrize("path", SOLUTIONS, ids=[p.stem for p in SOLUTIONS])
def test_solution_executes(path):
    nb = _read(path)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    markdown = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    n_exercises = len(re.findall(r"^## Exercise \d+", markdown, re.M))
    assert n_exercises >= 3 and len(re.findall(r"^\s*assert ", code, re.M)) >= n_exercises
    _execute(nb, path)


def test_the_course_covers_the_3d_view_and_a_widget():
    sources = {p.stem: "\n".join(c.source for c in _read(p).cells) for p in NOTEBOOKS}
    assert any("scene_view(" in s for s in sources.values())
    assert any("residual_panel(" in s for s in sources.values())


@pytest.mark.slow
def test_build_course_writes_html_with_the_3d_view_and_static_figures(tmp_path):
    """notebooks/build_course.py (what `./run.sh course` runs) on notebook 01: a page with the embedded 3D
    view, plotly.js and the static copy of the interactive figure (a live widget needs a kernel), and an index."""
    pytest.importorskip("nbconvert")
    import importlib.util

    spec = importlib.util.spec_from_file_location("build_course", NOTEBOOK_DIR / "build_course.py")
    build_course = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build_course)
    records = build_course.build(tmp_path, small=True, include_solutions=False, only=["01"])
    assert [r["file"] for r in records] == [NOTEBOOKS[0].stem + ".html"] and records[0]["error"] is None
    page = (tmp_path / records[0]["file"]).read_text(encoding="utf-8")
    assert VISER_EMBED in page and re.search(r"<iframe [^>]*srcdoc=", page)  # nbconvert reorders attributes
    assert ".newPlot(" in page and "plotly" in page.lower()
    assert records[0]["file"] in (tmp_path / "index.html").read_text(encoding="utf-8")
    assert build_course.main([str(tmp_path / "none"), "--only", "99"]) == 1  # nothing built is a failure
