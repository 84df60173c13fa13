"""The course as a student and a lecturer get it (docs/course.md, issue 27).

* Opening and running a notebook in JupyterLab changes no tracked file: jupytext's contents manager (what
  JupyterLab saves through) reads every course file as a notebook and writes it back byte for byte after a run
  added outputs and the metadata JupyterLab records, and creates no paired ``.ipynb``.
* The built hand-outs work offline (``notebooks/build_course.py``, checked in headless Chromium with the
  network blocked: ``tests/course_pages.py``).
* ``notebooks/`` copied alone to an empty folder runs against the installed package.
"""

from __future__ import annotations

import asyncio
import shutil
from pathlib import Path

import pytest

NOTEBOOK_DIR = Path(__file__).parent.parent / "notebooks"
COURSE_FILES = [*sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.py")),
                *sorted((NOTEBOOK_DIR / "solutions").glob("[0-9][0-9]_*.py"))]


def _tracked_copy(tmp_path: Path) -> Path:
    """notebooks/ as a fresh clone has it (the course files and the jupytext configuration)."""
    dest = tmp_path / "notebooks"
    shutil.copytree(NOTEBOOK_DIR, dest, ignore=shutil.ignore_patterns("*.ipynb", "__pycache__", ".ipynb_checkpoints"))
    return dest


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and ".ipynb_checkpoints" not in p.parts}


def test_opening_and_running_a_notebook_in_jupyterlab_changes_no_tracked_file(tmp_path):
    jupytext = pytest.importorskip("jupytext")
    pytest.importorskip("jupyter_server")
    from jupyter_server.services.contents.largefilemanager import AsyncLargeFileManager

    root = _tracked_copy(tmp_path)
    before = {name: (root / name).read_bytes() for name in _files(root)}
    manager = jupytext.build_async_jupytext_contents_manager_class(AsyncLargeFileManager)(root_dir=str(root))

    async def open_run_save(name: str) -> None:
        model = await manager.get(name)
        assert model["type"] == "notebook", f"{name} opens as {model['type']}, not as a notebook"
        nb = model["content"]
        # what JupyterLab and a kernel add: kernel and language, widget state, outputs, per-cell records
        nb["metadata"]["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
        nb["metadata"]["language_info"] = {"name": "python", "version": "3.11.2", "file_extension": ".py"}
        nb["metadata"]["widgets"] = {"application/vnd.jupyter.widget-state+json": {"state": {}, "version_major": 2}}
        for k, cell in enumerate(nb["cells"]):
            if cell["cell_type"] == "code":
                cell["execution_count"] = k + 1
                cell["outputs"] = [{"output_type": "stream", "name": "stdout", "text": "ran\n"}]
                cell["metadata"].update({"execution": {"iopub.status.busy": "2026-11-25T23:00:00Z"},
                                         "scrolled": True, "collapsed": False, "trusted": True})
        await manager.save(model, name)

    async def all_files() -> None:
        for name in sorted(before):
            if name.endswith(".py") and name.split("/")[-1][:2].isdigit():
                await open_run_save(name)

    asyncio.run(all_files())
    after = _files(root)
    assert after == set(before), f"files created or removed: {sorted(after ^ set(before))}"
    changed = [name for name in sorted(before) if (root / name).read_bytes() != before[name]]
    assert not changed, f"saving rewrote tracked files: {changed}"


def test_every_course_file_is_in_the_canonical_form_jupytext_writes():
    """No header, no metadata but tags: what the repository's jupytext.toml writes (so a save is a no-op)."""
    jupytext = pytest.importorskip("jupytext")
    from jupytext.config import load_jupytext_configuration_file

    config = load_jupytext_configuration_file(str(NOTEBOOK_DIR / "jupytext.toml"))
    assert config.formats in ("py:percent", ["py:percent"]) and config.notebook_metadata_filter == "-all"
    for path in COURSE_FILES:
        text = path.read_text(encoding="utf-8")
        nb = jupytext.reads(text, fmt="py:percent")
        assert jupytext.writes(nb, fmt="py:percent", config=config) == text, (
            f"{path.name} is not in the form notebooks/jupytext.toml writes, so saving it from JupyterLab would "
            "change it: remove its '# ---' YAML header and any cell metadata but tags (docs/course.md, rules for "
            "a new notebook)")


# ------------------------------------------------------------------------------------------ the built course
VISER_EMBED = "__VISER_EMBED_DATA__"
WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"


def _load_build_course(folder: Path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("build_course_copy", folder / "build_course.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _executed_notebook_problems(name: str, nb) -> list[str]:
    """The inline 3D view and the live widgets (with their static copies) a notebook's source promises."""
    source = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    outputs = [o for c in nb.cells for o in c.get("outputs", [])]
    html = [o["data"].get("text/html", "") for o in outputs if "data" in o]
    problems = []
    if "scene_view(" in source and not any(VISER_EMBED in h for h in html):
        problems.append(f"{name}: scene_view( in the source but no inline 3D view in the outputs")
    if "interactive_figure(" in source or "residual_panel(" in source:
        widgets = [o for o in outputs if WIDGET_VIEW in o.get("data", {})]
        if not widgets or not all(".newPlot(" in o["data"].get("text/html", "") for o in widgets):
            problems.append(f"{name}: a live widget without its static figure copy")
    return problems


@pytest.mark.slow
@pytest.mark.browser
@pytest.mark.parametrize("half", ["notebooks", "solutions"])
def test_the_course_built_from_a_copied_notebooks_folder_works_offline(tmp_path, half):
    """The acceptance check of issue 27 (each course file executes once; the notebooks and the solutions are two
    tests so that the parallel test run can build them at the same time):

    * ``notebooks/`` alone is copied to an empty folder and the course is built THERE (small sizes) with its own
      ``build_course.py``: every notebook and solution runs outside the checkout against the installed package
      (data through ``explorer.assets``, nothing read beside the notebook but what the folder holds);
    * every notebook and solution executes without error, and the executed notebooks hold the inline 3D views and
      the live widgets with their static copies;
    * every built page opens in headless Chromium with the network blocked and requests nothing off the disk,
      shows its equations rendered (MathML, no raw ``$`` in the prose), and draws every figure and 3D view.
    """
    pytest.importorskip("nbclient")
    pytest.importorskip("latex2mathml")
    import os

    from tests import course_pages

    if not os.path.exists(course_pages.CHROMIUM):
        pytest.skip("needs Debian chromium at /usr/bin/chromium")
    pytest.importorskip("playwright.sync_api")
    import nbformat

    empty = tmp_path / "elsewhere"
    empty.mkdir()
    shutil.copytree(NOTEBOOK_DIR, empty / "notebooks",
                    ignore=shutil.ignore_patterns("*.ipynb", "__pycache__", ".ipynb_checkpoints"))
    out = tmp_path / "course"
    build_course = _load_build_course(empty / "notebooks")
    cwd = os.getcwd()
    os.chdir(empty)  # nothing of the checkout is reachable as a relative path
    try:
        records = build_course.build(out, small=True, write_ipynb=True, include_notebooks=half == "notebooks",
                                     include_solutions=half == "solutions")
    finally:
        os.chdir(cwd)
    expected = [p for p in COURSE_FILES if (p.parent.name == "solutions") == (half == "solutions")]
    n_files = len(expected)
    assert [r["file"].split("/")[-1] for r in records] == [p.stem + ".html" for p in expected], \
        "every NN_*.py of the folder is built"
    problems = [f"{r['file']}: {r['error']}" for r in records if r["error"]]
    for ipynb in sorted(out.rglob("*.ipynb")):
        problems += _executed_notebook_problems(ipynb.name, nbformat.read(ipynb, as_version=4))
    assert not problems, "\n".join(problems)

    sources = {p.stem: p.read_text(encoding="utf-8") for p in expected}
    reports = course_pages.check_folder(out)
    assert len(reports) == n_files + 1  # and the index
    for r in reports:
        stem = r.page.removesuffix(".html")
        problems += r.problems(needs_math="$" in sources.get(stem, ""))
    assert not problems, "\n".join(problems)
    assert sum(r.n_views for r in reports) >= sum("scene_view(" in s for s in sources.values())
    if half == "notebooks":  # most notebooks' interactive cell is a figure
        assert sum(r.n_figures for r in reports) >= n_files // 2


@pytest.mark.slow
@pytest.mark.browser
def test_a_double_click_in_jupyterlab_opens_a_course_file_as_a_notebook(tmp_path):
    """JupyterLab (this venv's, with ``notebooks/jupyterlab_overrides.json`` as its settings overrides, which
    ``./run.sh setup`` installs) on a copy of notebooks/: double-clicking ``01_*.py`` in the file browser opens a
    notebook (cells), not a text editor; and nothing in the folder changes."""
    import json
    import os
    import socket
    import subprocess
    import sys
    import time

    from tests import course_pages

    if not os.path.exists(course_pages.CHROMIUM):
        pytest.skip("needs Debian chromium at /usr/bin/chromium")
    sync_api = pytest.importorskip("playwright.sync_api")
    pytest.importorskip("jupyterlab")
    root = _tracked_copy(tmp_path)
    before = {name: (root / name).read_bytes() for name in _files(root)}
    settings = tmp_path / "lab-settings"
    settings.mkdir()
    overrides = json.loads((NOTEBOOK_DIR / "jupyterlab_overrides.json").read_text(encoding="utf-8"))
    (settings / "overrides.json").write_text(json.dumps(overrides), encoding="utf-8")
    port = next(p for p in range(8170, 8180) if socket.socket().connect_ex(("127.0.0.1", p)) != 0)
    token = "course-test"
    env = {**os.environ, "JUPYTER_CONFIG_DIR": str(tmp_path / "jupyter-config"),
           "JUPYTERLAB_SETTINGS_DIR": str(tmp_path / "user-settings"),
           "JUPYTERLAB_WORKSPACES_DIR": str(tmp_path / "workspaces")}
    server = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", "--no-browser", f"--port={port}", "--ServerApp.ip=127.0.0.1",
         f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root}",
         f"--LabServerApp.app_settings_dir={settings}", "--allow-root"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        while socket.socket().connect_ex(("127.0.0.1", port)) != 0:
            assert server.poll() is None and time.monotonic() - t0 < 120, "JupyterLab did not start"
            time.sleep(0.5)
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=course_pages.CHROMIUM, args=course_pages.ARGS)
            try:
                page = browser.new_page(viewport={"width": 1300, "height": 900})
                page.set_default_timeout(180_000)
                page.goto(f"http://127.0.0.1:{port}/lab?token={token}")
                item = page.locator(".jp-DirListing-item", has_text="01_frame_vs_pushbroom.py")
                item.first.dblclick()
                page.wait_for_selector(".jp-NotebookPanel .jp-MarkdownCell", state="visible")
                page.wait_for_timeout(1000)
                page.screenshot(path=str(tmp_path / "lab.png"))
                assert page.locator(".jp-NotebookPanel .jp-Cell").count() > 3
                assert page.locator(".jp-FileEditor:visible").count() == 0
            finally:
                browser.close()
    finally:
        server.terminate()
        try:
            server.wait(30)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait(10)
    assert _files(root) == set(before)
    assert all((root / name).read_bytes() == data for name, data in before.items())


def test_the_build_renders_markdown_math_to_mathml_and_leaves_code_alone():
    pytest.importorskip("latex2mathml")
    build_course = _load_build_course(NOTEBOOK_DIR)
    rendered: dict[str, str] = {}
    text = ("Inline $x_i^2$ and `$HOME` in code, an escaped \\$5, then\n\n$$ t = \\frac{a}{b} $$\n\n"
            "```\necho $PATH $x$\n```\n")
    out = build_course._math_to_placeholders(text, rendered)
    assert len(rendered) == 2 and "`$HOME`" in out and "echo $PATH $x$" in out and "\\$5" in out
    inline, display = (rendered[k] for k in sorted(rendered))
    assert inline.startswith("<math ") and 'display="inline"' in inline and "<msubsup>" in inline
    assert 'display="block"' in display and "<mfrac>" in display and 'alttext="t = \\frac{a}{b}"' in display


def test_the_build_draws_plotly_json_outputs_with_the_pages_plotly_js():
    nbformat = pytest.importorskip("nbformat")
    build_course = _load_build_course(NOTEBOOK_DIR)
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell("fig")
    spec = {"data": [{"type": "bar", "y": [1, 2]}], "layout": {"height": 300, "title": {"text": "</script>"}}}
    cell.outputs = [nbformat.v4.new_output("display_data", data={build_course.PLOTLY_MIME: spec})]
    nb.cells = [nbformat.v4.new_markdown_cell("# T\n\n$a$"), cell]
    page_nb, rendered = build_course.prepare_for_html(nb)
    html = page_nb.cells[1].outputs[0]["data"]["text/html"]
    assert 'Plotly.newPlot("pbx-fig-' in html and "height:300px" in html and "</script>\"" not in html
    assert "<script src=" not in html and nb.cells[0].source == "# T\n\n$a$"  # the original is untouched
    page = build_course.to_html(nb)
    assert page.count("plotly.js v") == 1 and "cdnjs" not in page and "require.min.js" not in page
    assert "<math " in page and "$a$" not in page
