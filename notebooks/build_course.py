"""Execute the course notebooks and write them as self-contained HTML hand-outs.

Usage::

    python notebooks/build_course.py OUT_DIR [--small] [--no-solutions] [--only 01,05] [--ipynb]

Every ``notebooks/NN_*.py`` (jupytext percent file; a new notebook is picked up by its name alone) and
``notebooks/solutions/NN_*.py`` is read with jupytext, executed with nbclient (working directory: its own
folder) and exported with nbconvert's ``lab`` template to ``OUT_DIR/NN_name.html`` and
``OUT_DIR/solutions/NN_name.html``; ``OUT_DIR/index.html`` links them in course order with the time each
took.  ``--small`` sets ``PUSHBROOM_NB_SMALL=1`` (what CI runs).  The lecturer's guide, with the rules a
new notebook follows: ``docs/course.md``.

The pages load nothing from the network, so the folder works from a USB stick:

* equations are rendered at build time to MathML (``latex2mathml``), which browsers draw natively: no
  MathJax, no CDN;
* every Plotly figure is drawn by ONE copy of plotly.js embedded in the page's head (the installed
  ``plotly`` package's bundle); the kernel runs with the ``plotly_mimetype`` renderer and the build turns
  each figure into a ``Plotly.newPlot`` call, and the static copies of the live widgets
  (:mod:`explorer.notebook`) use the same ``window.Plotly``;
* the inline 3D views are viser's static viewer with the scene embedded (an ``<iframe srcdoc>``);
* nbconvert's CDN scripts (require.js, MathJax, mermaid, the widget manager) are left out of the
  template; live widgets need a kernel, so the pages show their static copies.

A failing notebook is reported (its partial HTML is still written) and the exit status is 1.
"""

from __future__ import annotations

import argparse
import copy
import html
import json
import os
import re
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
STATIC_PRIORITY = ["application/javascript", "text/html", "text/markdown", "image/svg+xml", "text/latex", "image/png",
                   "image/jpeg", "text/plain"]
"""nbconvert's HTML output priority without ``widget-view``: a live widget needs a kernel, so the page shows the
static ``text/html`` copy that :mod:`explorer.notebook` widgets carry."""
PLOTLY_MIME = "application/vnd.plotly.v1+json"

TEMPLATE = """{%- extends 'index.html.j2' -%}
{%- block html_head_js -%}{%- endblock html_head_js -%}
{%- block jupyter_widgets -%}{%- endblock jupyter_widgets -%}
{%- block html_head_js_mathjax -%}
<style>math[display="block"]{display:block;margin:0.7em 0;overflow-x:auto}math{font-size:1.1em}</style>
{%- endblock html_head_js_mathjax -%}
{%- block html_head_js_mermaidjs -%}
{%- if resources.pbx_plotly_js -%}<script type="text/javascript">{{ resources.pbx_plotly_js }}</script>{%- endif -%}
{%- endblock html_head_js_mermaidjs -%}
"""
"""The ``lab`` template without its CDN scripts (require.js, MathJax, mermaid, the widget manager), with
plotly.js once in the head when the page has a figure."""

_CODE = re.compile(r"(```.*?```|~~~.*?~~~|`[^`\n]*`)", re.S)
_MATH = re.compile(r"\$\$(.+?)\$\$|(?<![\\$])\$(?![\s$])(.+?)(?<![\s\\$])\$(?!\d)", re.S)


def course_files(include_solutions: bool = True, only: list[str] | None = None, *,
                 include_notebooks: bool = True) -> list[Path]:
    """Notebooks in course order, then their solutions; ``only`` filters by the two-digit number.

    Every ``NN_*.py`` in ``notebooks/`` and ``notebooks/solutions/`` is a course file: a new notebook needs
    no registration here."""
    files = sorted(HERE.glob("[0-9][0-9]_*.py")) if include_notebooks else []
    if include_solutions:
        files += sorted((HERE / "solutions").glob("[0-9][0-9]_*.py"))
    if only:
        files = [f for f in files if f.name[:2] in only]
    return files


def execute(path: Path, *, small: bool, timeout: int = 900):
    """Read a jupytext file and execute it; returns (notebook, seconds, error text or None)."""
    import jupytext
    import nbclient

    nb = jupytext.read(path)
    nb.metadata.setdefault("kernelspec", {"name": "python3", "display_name": "Python 3", "language": "python"})
    # figures as their JSON (what JupyterLab draws); to_html turns them into plotly.js calls
    env = {**os.environ, "PLOTLY_RENDERER": "plotly_mimetype"}
    env["PUSHBROOM_NB_SMALL"] = "1" if small else "0"
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3", store_widget_state=True,
                                     resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    error = None
    try:
        client.execute(env=env)
    except Exception as exc:  # noqa: BLE001 - reported per notebook, the others still run
        error = f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else ''}"
    return nb, time.perf_counter() - t0, error


def latex_to_mathml(tex: str, display: bool) -> str:
    """One TeX formula as MathML (``latex2mathml``), with the TeX kept in ``alttext``."""
    from latex2mathml.converter import convert

    mathml = convert(tex.strip(), display="block" if display else "inline")
    return mathml.replace("<math ", f'<math alttext="{html.escape(tex.strip(), quote=True)}" ', 1)


def _math_to_placeholders(text: str, rendered: dict[str, str]) -> str:
    """Replace the ``$...$`` / ``$$...$$`` formulas of a markdown text (outside code) by placeholders whose
    MathML is stored in ``rendered``; markdown never sees the TeX."""
    def one(m: re.Match) -> str:
        key = f"PBXMATH{len(rendered):05d}X"
        display = m.group(1) is not None
        rendered[key] = latex_to_mathml(m.group(1) if display else m.group(2), display)
        return key

    parts = _CODE.split(text)
    return "".join(p if i % 2 else _MATH.sub(one, p) for i, p in enumerate(parts))


def figure_html(spec: dict) -> str:
    """A Plotly figure (its JSON, as the ``plotly_mimetype`` renderer writes it) drawn by the page's plotly.js."""
    import uuid

    div = f"pbx-fig-{uuid.uuid4().hex}"
    layout = spec.get("layout", {})
    height = layout.get("height") or 450
    config = {"responsive": True, **spec.get("config", {})}
    payload = json.dumps({"data": spec.get("data", []), "layout": layout, "config": config}).replace("</", "<\\/")
    return (f'<div id="{div}" class="pbx-figure" style="height:{int(height)}px;width:100%"></div>'
            f'<script type="text/javascript">(function(){{var s={payload};'
            f'Plotly.newPlot("{div}",s.data,s.layout,s.config);}})();</script>')


def prepare_for_html(nb) -> tuple[object, dict[str, str]]:
    """A copy of an executed notebook ready for the offline page: math as placeholders, Plotly JSON outputs as
    ``text/html`` drawing calls, no widget state (the page shows the widgets' static copies)."""
    nb = copy.deepcopy(nb)
    nb.metadata.pop("widgets", None)
    rendered: dict[str, str] = {}
    for cell in nb.cells:
        if cell.cell_type == "markdown":
            cell.source = _math_to_placeholders(cell.source, rendered)
        for out in cell.get("outputs", []):
            data = out.get("data", {})
            if PLOTLY_MIME in data and "text/html" not in data:
                data["text/html"] = figure_html(data[PLOTLY_MIME])
    return nb, rendered


def to_html(nb) -> str:
    """The self-contained HTML page of an executed notebook (see the module docstring)."""
    from jinja2 import DictLoader
    from nbconvert import HTMLExporter
    from plotly.offline import get_plotlyjs
    from traitlets.config import Config

    page_nb, rendered = prepare_for_html(nb)
    config = Config({"NbConvertBase": {"display_data_priority": STATIC_PRIORITY}})
    exporter = HTMLExporter(template_name="lab", config=config,
                            extra_loaders=[DictLoader({"pushbroom_course.html.j2": TEMPLATE})])
    exporter.template_file = "pushbroom_course.html.j2"
    has_figure = any(".newPlot(" in o.get("data", {}).get("text/html", "")
                     for c in page_nb.cells for o in c.get("outputs", []))
    resources = {"pbx_plotly_js": get_plotlyjs().replace("</script", "<\\/script") if has_figure else ""}
    body, _ = exporter.from_notebook_node(page_nb, resources=resources)
    for key, mathml in rendered.items():
        body = body.replace(key, mathml)
    return body


def build(out_dir: Path, *, small: bool = False, include_solutions: bool = True, only: list[str] | None = None,
          write_ipynb: bool = False, timeout: int = 900, include_notebooks: bool = True) -> list[dict]:
    """Execute and export every course file; returns one record per file (name, seconds, error).

    ``include_notebooks=False`` builds the solutions alone (CI builds the two halves in parallel tests)."""
    import nbformat

    out_dir.mkdir(parents=True, exist_ok=True)
    records = []
    for path in course_files(include_solutions, only, include_notebooks=include_notebooks):
        sub = "solutions" if path.parent.name == "solutions" else ""
        dest = out_dir / sub
        dest.mkdir(parents=True, exist_ok=True)
        nb, seconds, error = execute(path, small=small, timeout=timeout)
        try:
            page = to_html(nb)
        except Exception as exc:  # noqa: BLE001 - e.g. an equation latex2mathml cannot convert: reported
            page, error = "", error or f"HTML export: {type(exc).__name__}: {exc}"
        (dest / f"{path.stem}.html").write_text(page, encoding="utf-8")
        if write_ipynb:
            nbformat.write(nb, dest / f"{path.stem}.ipynb")
        rec = {"file": f"{sub + '/' if sub else ''}{path.stem}.html", "title": _title(nb, path), "seconds": seconds,
               "error": error}
        records.append(rec)
        print(f"{rec['file']:55s} {seconds:7.1f} s  {'FAILED: ' + error if error else 'ok'}", flush=True)
    _write_index(out_dir, records, small)
    return records


def _title(nb, path: Path) -> str:
    for cell in nb.cells:
        if cell.cell_type == "markdown":
            for line in cell.source.splitlines():
                if line.startswith("# "):
                    return line[2:].strip()
    return path.stem


def _write_index(out_dir: Path, records: list[dict], small: bool) -> None:
    items = []
    for r in records:
        status = f" <b style='color:#b00'>failed: {html.escape(r['error'])}</b>" if r["error"] else ""
        items.append(f"<li><a href='{r['file']}'>{html.escape(r['title'])}</a> "
                     f"<small>({r['seconds']:.0f} s to run)</small>{status}</li>")
    total = sum(r["seconds"] for r in records)
    mode = "small mode (PUSHBROOM_NB_SMALL=1)" if small else "full size"
    (out_dir / "index.html").write_text(
        "<!doctype html><meta charset='utf-8'><title>Pushbroom geometry: the course</title>"
        "<h1>Pushbroom geometry: the course</h1>"
        f"<p>Executed notebooks, {mode}, {total:.0f} s in all. Lecturer's guide: docs/course.md.</p>"
        f"<ol>{''.join(items)}</ol>", encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    """Command line entry point; returns the exit status (1 if a notebook failed)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out_dir", nargs="?", default="course_html", help="output folder (default: course_html)")
    ap.add_argument("--small", action="store_true", help="small sizes (PUSHBROOM_NB_SMALL=1), as CI runs them")
    ap.add_argument("--no-solutions", action="store_true", help="skip notebooks/solutions/")
    ap.add_argument("--only", default="", help="comma-separated notebook numbers, e.g. 01,05")
    ap.add_argument("--ipynb", action="store_true", help="also write the executed .ipynb files")
    ap.add_argument("--timeout", type=int, default=900, help="per-cell timeout, seconds")
    args = ap.parse_args(argv)
    only = [s.strip().zfill(2) for s in args.only.split(",") if s.strip()] or None
    t0 = time.perf_counter()
    records = build(Path(args.out_dir), small=args.small, include_solutions=not args.no_solutions, only=only,
                    write_ipynb=args.ipynb, timeout=args.timeout)
    failed = [r for r in records if r["error"]]
    print(f"{len(records)} notebooks in {time.perf_counter() - t0:.0f} s -> {Path(args.out_dir) / 'index.html'}"
          + (f"; {len(failed)} FAILED" if failed else ""))
    return 1 if failed or not records else 0


if __name__ == "__main__":
    sys.exit(main())
