"""Execute the course notebooks and write them as HTML (figures, 3D views and widgets included).

Usage::

    python notebooks/build_course.py OUT_DIR [--small] [--no-solutions] [--only 01,05] [--ipynb]

Every ``notebooks/NN_*.py`` (jupytext percent file) and ``notebooks/solutions/NN_*.py`` is read
with jupytext, executed with nbclient (working directory: its own folder, so relative paths
resolve as in JupyterLab) and exported with nbconvert's HTML exporter to ``OUT_DIR/NN_name.html``
and ``OUT_DIR/solutions/NN_name.html``; ``OUT_DIR/index.html`` links them in course order with the
time each took.  ``--small`` sets ``PUSHBROOM_NB_SMALL=1`` (what CI runs).  The lecturer's guide is
``docs/course.md``.

Plotly figures are written with plotly.js embedded once per page (``notebook`` renderer), so the
pages work offline; the inline 3D views are viser's static viewer with the scene embedded.  A
failing notebook is reported (its partial HTML is still written) and the exit status is 1.
"""

from __future__ import annotations

import argparse
import html
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
STATIC_PRIORITY = ["application/javascript", "text/html", "text/markdown", "image/svg+xml", "text/latex", "image/png",
                   "image/jpeg", "text/plain"]
"""nbconvert's HTML output priority without ``widget-view``: a live widget needs a kernel, so the page shows the
static ``text/html`` copy that :mod:`explorer.notebook` widgets carry."""


def course_files(include_solutions: bool = True, only: list[str] | None = None) -> list[Path]:
    """Notebooks in course order, then their solutions; ``only`` filters by the two-digit number."""
    files = sorted(HERE.glob("[0-9][0-9]_*.py"))
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
    env = {**os.environ, "PLOTLY_RENDERER": "notebook"}
    if small:
        env["PUSHBROOM_NB_SMALL"] = "1"
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3", store_widget_state=True,
                                     resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    error = None
    try:
        client.execute(env=env)
    except Exception as exc:  # noqa: BLE001 - reported per notebook, the others still run
        error = f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1] if str(exc).strip() else ''}"
    return nb, time.perf_counter() - t0, error


def to_html(nb) -> str:
    """nbconvert's HTML (lab template) of an executed notebook; widgets as their static copies."""
    from nbconvert import HTMLExporter
    from traitlets.config import Config

    config = Config({"NbConvertBase": {"display_data_priority": STATIC_PRIORITY}})
    exporter = HTMLExporter(template_name="lab", config=config)
    body, _ = exporter.from_notebook_node(nb)
    return body


def build(out_dir: Path, *, small: bool = False, include_solutions: bool = True, only: list[str] | None = None,
          write_ipynb: bool = False, timeout: int = 900) -> list[dict]:
    """Execute and export every course file; returns one record per file (name, seconds, error)."""
    import nbformat

    out_dir.mkdir(parents=True, exist_ok=True)
    records = []
    for path in course_files(include_solutions, only):
        sub = "solutions" if path.parent.name == "solutions" else ""
        dest = out_dir / sub
        dest.mkdir(parents=True, exist_ok=True)
        nb, seconds, error = execute(path, small=small, timeout=timeout)
        (dest / f"{path.stem}.html").write_text(to_html(nb), encoding="utf-8")
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
