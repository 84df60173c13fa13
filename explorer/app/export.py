"""Export what the explorer's panels show: ``summary.json``, ``residuals.csv``, ``panels.html``, ``timing.json``,
``timing.js``.

``pushbroom explore <source> --export DIR`` (and the GUI's *Export* button, as a zip) fits
every chosen method on the SCOPs and evaluates it on **every** SCP -- never a subsample --
then writes

* ``summary.json`` -- ``{"source": {...}, "settings": {...}, "truth": {"model", "body", ...},
  "methods": {name: {"rmse_row_px", "rmse_col_px", "max_row_px", "max_col_px", "n_valid", "n_invalid",
  "n_refused", "n_not_converged", "n_outside_image", "n_scops", "ce_per_point", "error", "warnings"}},
  "accuracy_vs_scops": {name: [{"n_scops", "rmse_px", "dr_max_px", "n_evaluated"}, ...]} or null,
  "accuracy_vs_scops_failed": {name: [{"n_scops", "error"}, ...]} or null,
  "stand_in": {"model", "against", "rmse_row_px", ...} or null, "run_dependent": {file: why}}``: ``truth``
  names the sensor every residual is measured against (its own ground to image), ``stand_in`` the
  model-vs-model map of a file source (the MPC fitted to a CSM camera, the vendor RPC of a rigorous DIMAP / DG
  model, the RPC against its resected MPC with ``--as-mpc``) against it; a method the sensor cannot serve (a search
  method on an RPC, which has no scanlines) has ``"unavailable": reason`` and no numbers; ``accuracy_vs_scops``
  the GUI's accuracy-vs-SCOPs sweep (each method refitted at every density of
  :data:`explorer.app.model.SCOP_DENSITIES`, evaluated on the model's ``sweep_points`` SCPs), and
  ``accuracy_vs_scops_failed`` the densities where a method could not be fitted or evaluated, with the reason
  (they have no point in the sweep; the panel names them);
* ``residuals.csv`` -- one row per check point per method (and per stand-in, method ``stand-in``):
  ``method, scp_index, row_px, col_px, row_residual_px, col_residual_px, status, x_m, y_m, z_m`` (the
  sensor's own image position of the SCP, estimated minus exact, empty where the method gave no answer;
  status as in :data:`explorer.app.model.STATUS_NAMES`; the SCP's body-fixed coordinates, ECEF on the Earth),
  plus ``line, sample`` for an ISD source (the camera's own image position, usgscsm's convention:
  ``row + 0.5, col + 0.5``);
* ``panels.html`` -- the GUI's panels in one page that opens offline (plotly.js inlined, nothing loaded from
  the network): the residual maps (row and column rasters of every check point, the stand-in's beside them),
  the accuracy-vs-SCOPs sweep, the summary table and the Timing panel;
* ``timing.json`` -- **the one run-dependent file**: the fit and evaluation times measured on this run
  (``{"methods": {name: {"fit_s", "eval_s", "n_evaluated", "n_scops"}}, "sweep_s"}``), which depend on the
  machine and its load;
* ``timing.js`` -- the same numbers as a script (``window.PUSHBROOM_TIMING = {...};``) that ``panels.html``
  loads from its own folder (a relative ``<script src="timing.js">``, no network) to fill its Timing panel
  when opened; without it the panel says where the times are.

Reproducible: the points are seeded grids, the fits and evaluations take no timing-dependent
decision (no time budget), numbers are written with 17 significant digits and JSON keys sorted, and
plotly's element ids are fixed, so two runs with the same settings give byte-identical ``summary.json``,
``residuals.csv`` and ``panels.html``; only the files named in ``summary.json["run_dependent"]``
(:data:`RUN_DEPENDENT`) differ (docs/explorer.md#export).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, kernel_array
from explorer.app.model import STATUS_NAMES, SWEEP_PURPOSE, ExplorerModel, FitRecord, Settings, sensor_truth
from explorer.evaluate import STAND_IN_METHOD, Evaluation, evaluate_stand_in
from explorer.float_text import MAX_FIELD_BYTES, csv_lines
from explorer.io_atomic import write_folder_atomic
from explorer.sensor import StandIn
from explorer.sources import stand_in_truth, table_coverage_text

CSV_COLUMNS = ("method", "scp_index", "row_px", "col_px", "row_residual_px", "col_residual_px", "status",
               "x_m", "y_m", "z_m")
"""Columns of ``residuals.csv``; an ISD source adds ``line, sample`` (:data:`NATIVE_PIXEL_COLUMNS`)."""
NATIVE_PIXEL_COLUMNS = ("line", "sample")
TIMING_JSON, TIMING_JS = "timing.json", "timing.js"
RUN_DEPENDENT = {
    TIMING_JSON: "fit and evaluation times measured on this run (they depend on the machine and its load); "
                 "every other file is byte-identical for the same settings",
    TIMING_JS: f"the same times as {TIMING_JSON}, as the script panels.html loads to fill its Timing panel",
}
"""The export's run-dependent files and why; written as ``summary.json["run_dependent"]``."""
# STAND_IN_METHOD (explorer.evaluate): the method name of the stand-in's rows and map




def _finite_or_none(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def residuals_csv(evaluations: dict[str, Evaluation], status: dict[str, np.ndarray], scps: Any,
                  body_fixed: np.ndarray | None = None, native_pixels: bool = False) -> bytes:
    """The CSV text (bytes, LF line ends) of every evaluated point of every method.

    ``row_px, col_px`` are the sensor's own ground to image of the check point, ``x_m, y_m, z_m`` its
    body-fixed coordinates (``body_fixed``, (N, 3)); with ``native_pixels`` (a USGS CSM camera) also
    ``line, sample`` = ``row + 0.5, col + 0.5`` (usgscsm's convention: the camera's own image position).
    Numbers have 17 significant digits (``%.17g``: an exact round trip); a non-finite number is an empty field.
    The bytes are written by a compiled kernel (:func:`explorer.float_text.csv_lines`: exact ``%.17g`` digits
    in integer arithmetic, no Python string per number); without numba by Python's own formatting
    (:func:`_residuals_csv_python`), the same bytes.
    """
    columns = CSV_COLUMNS + (NATIVE_PIXEL_COLUMNS if native_pixels else ())
    header = (",".join(columns) + "\n").encode()
    row, col = np.asarray(scps.row, dtype=np.float64), np.asarray(scps.col, dtype=np.float64)
    xyz = np.full((len(scps), 3), np.nan) if body_fixed is None else np.asarray(body_fixed, dtype=np.float64)
    groups = [(name, ev) for name, ev in evaluations.items() if np.asarray(ev.evaluated_index).size]
    if not groups:
        return header
    index = np.concatenate([np.asarray(ev.evaluated_index, dtype=np.int64) for _, ev in groups])
    mark = np.zeros(len(row), dtype=bool)  # the columns every method shares are formatted once per check point
    mark[index] = True
    used = np.flatnonzero(mark)  # = np.unique(index) (sorted), without its sort or hash of 700,000 indices
    shared = [row[used], col[used], xyz[used, 0], xyz[used, 1], xyz[used, 2]]
    if native_pixels:
        shared += [row[used] + 0.5, col[used] + 0.5]
    at = np.full(len(row), -1, dtype=np.int64)  # check point index -> position in ``used``
    at[used] = np.arange(used.size)
    sizes = [np.asarray(ev.evaluated_index).size for _, ev in groups]
    parts: dict[str, list[np.ndarray]] = {"row residuals": [], "column residuals": [], "statuses": []}
    for (name, ev), n in zip(groups, sizes, strict=True):
        for what, values in zip(parts, (ev.residual_row, ev.residual_col, status[name]), strict=True):
            values = np.asarray(values).ravel()
            if values.size != n:
                raise ValueError(f"residuals_csv: method {name!r} has {n} evaluated points but {values.size} "
                                 f"{what}")
            parts[what].append(values)
    label = np.concatenate(parts["statuses"]).astype(np.int64)
    if label.size and (label.min() < -len(STATUS_NAMES) or label.max() >= len(STATUS_NAMES)):
        raise IndexError(f"residuals_csv: a status outside 0..{len(STATUS_NAMES) - 1}")
    if not NUMBA_AVAILABLE:  # the same bytes by Python's formatting (checked above: the same errors)
        return _residuals_csv_python(evaluations, status, scps, body_fixed, native_pixels)
    label %= len(STATUS_NAMES)
    prefixes = [(name + ",").encode() for name, _ in groups]
    labels = [("," + name + ",").encode() for name in STATUS_NAMES]
    per_line = 24 + 2 * MAX_FIELD_BYTES + max(len(t) for t in labels) + len(shared) * (MAX_FIELD_BYTES + 1)
    bound = len(header) + sum(n * (len(p) + per_line) for p, n in zip(prefixes, sizes, strict=True))
    out = np.empty(bound, dtype=np.uint8)
    out[:len(header)] = np.frombuffer(header, dtype=np.uint8)
    end = csv_lines(out, len(header), kernel_array(np.stack(shared, axis=1)), 2,
                    np.frombuffer(b"".join(prefixes), dtype=np.uint8).copy(),
                    np.cumsum([len(p) for p in prefixes]).astype(np.int64), np.cumsum(sizes).astype(np.int64),
                    index, at[index], kernel_array(np.concatenate(parts["row residuals"])),
                    kernel_array(np.concatenate(parts["column residuals"])), label,
                    np.frombuffer(b"".join(labels), dtype=np.uint8).copy(),
                    np.cumsum([len(t) for t in labels]).astype(np.int64))
    return out[:end].tobytes()


def _residuals_csv_python(evaluations: dict[str, Evaluation], status: dict[str, np.ndarray], scps: Any,
                          body_fixed: np.ndarray | None = None, native_pixels: bool = False) -> bytes:
    """:func:`residuals_csv` in Python (without numba): the same bytes, about 3x the CPU time."""
    columns = CSV_COLUMNS + (NATIVE_PIXEL_COLUMNS if native_pixels else ())
    xyz = np.full((len(scps), 3), np.nan) if body_fixed is None else np.asarray(body_fixed, dtype=np.float64)
    row, col = np.asarray(scps.row, dtype=np.float64), np.asarray(scps.col, dtype=np.float64)
    # The columns every method shares (the check point's row, col and body-fixed x, y, z) are formatted once per
    # check point, not once per method and point.  Each column is formatted as a whole (``str.__mod__`` mapped in
    # C) and the lines are put together by interleaving the columns' strings with the separators in one list and
    # joining it: no Python code runs per line (the %-format of one tuple per line took 1.2 s CPU for 15 maps of
    # 50,000 points; np.char formatting 3.3x as long); the same bytes.
    used = np.unique(np.concatenate([np.asarray(ev.evaluated_index, dtype=np.int64) for ev in evaluations.values()]
                                    or [np.zeros(0, np.int64)]))
    shared = [row[used], col[used], xyz[used, 0], xyz[used, 1], xyz[used, 2]]
    if native_pixels:
        shared += [row[used] + 0.5, col[used] + 0.5]
    heads = _joined([_formatted(shared[0]), _formatted(shared[1])], ",")
    tails = [t + "\n" for t in _joined([_formatted(c) for c in shared[2:]], ",")]
    at = np.full(len(row), -1, dtype=np.int64)  # check point index -> position in ``used``
    at[used] = np.arange(used.size)
    labels = ["," + name + "," for name in STATUS_NAMES]
    chunks = [",".join(columns) + "\n"]
    for name, ev in evaluations.items():
        idx = np.asarray(ev.evaluated_index)
        n = int(idx.size)
        if not n:
            continue
        pick = _picker(at[idx].tolist())
        pieces: list[str] = [""] * (10 * n)  # per line: name, index, row,col, residuals, status, x..z, line end
        pieces[0::10] = [name + ","] * n
        pieces[1::10] = ("%d\n" * n % tuple(idx.tolist())).split("\n")[:n]
        pieces[2::10] = [","] * n
        pieces[3::10] = pick(heads)
        pieces[4::10] = [","] * n
        pieces[5::10] = _formatted(np.asarray(ev.residual_row, dtype=np.float64))
        pieces[6::10] = [","] * n
        pieces[7::10] = _formatted(np.asarray(ev.residual_col, dtype=np.float64))
        pieces[8::10] = _picker(np.asarray(status[name]).tolist())(labels)
        pieces[9::10] = pick(tails)
        chunks.append("".join(pieces))
    return "".join(chunks).encode()


def _formatted(values: np.ndarray) -> list[str]:
    """Each number with 17 significant digits (``%.17g``), a non-finite one as an empty string."""
    n = int(values.size)
    out = ("%.17g\n" * n % tuple(values.tolist())).split("\n")[:n]  # one format call: 20 % faster than n calls
    for i in np.flatnonzero(~np.isfinite(values)).tolist():
        out[i] = ""
    return out


def _picker(index: list[int]) -> Callable[[list[str]], list[str]]:
    """``f(values) = [values[i] for i in index]`` (``operator.itemgetter``: the loop in C)."""
    from operator import itemgetter

    if len(index) == 1:
        return lambda values: [values[index[0]]]
    get = itemgetter(*index)
    return lambda values: list(get(values))


def _joined(columns: list[list[str]], sep: str) -> list[str]:
    """The columns' strings joined row by row with ``sep`` (one string per row)."""
    return [sep.join(t) for t in zip(*columns, strict=True)]


def method_summary(ev: Evaluation | None, status: np.ndarray | None, fit: FitRecord, error: str | None) -> dict:
    """The JSON entry of one method (see the module docstring); no timing (that is :func:`method_timing`)."""
    if fit.unavailable:  # the sensor lacks what the method needs (a search method on an RPC): the reason
        return {"unavailable": fit.unavailable, "error": None, "n_valid": 0, "n_invalid": 0}
    if ev is None:
        return {"error": error or fit.error, "n_valid": 0, "n_invalid": 0}
    r, c = np.asarray(ev.residual_row), np.asarray(ev.residual_col)
    ok_r, ok_c = np.isfinite(r), np.isfinite(c)
    counts = np.bincount(np.asarray(status, dtype=np.int64), minlength=len(STATUS_NAMES))
    return {
        "rmse_row_px": _finite_or_none(float(np.sqrt(np.mean(r[ok_r] ** 2))) if ok_r.any() else math.nan),
        "rmse_col_px": _finite_or_none(float(np.sqrt(np.mean(c[ok_c] ** 2))) if ok_c.any() else math.nan),
        "max_row_px": _finite_or_none(float(np.max(np.abs(r[ok_r]))) if ok_r.any() else math.nan),
        "max_col_px": _finite_or_none(float(np.max(np.abs(c[ok_c]))) if ok_c.any() else math.nan),
        "n_valid": int(ok_r.sum()), "n_invalid": int((~ok_r).sum()),
        "n_refused": int(counts[1]), "n_not_converged": int(counts[2]), "n_outside_image": int(counts[3]),
        "n_scops": int(fit.n_scops), "ce_per_point": float(ev.ce_evals_per_point), "error": None,
        "warnings": list(fit.warnings),
    }


def method_timing(ev: Evaluation | None, fit: FitRecord) -> dict:
    """The run-dependent entry of one method in ``timing.json``: ``fit_s``, ``eval_s`` (seconds, None without an
    evaluation), ``n_evaluated`` (the points ``eval_s`` was measured on) and ``n_scops``."""
    return {"fit_s": float(fit.fit_s), "eval_s": None if ev is None else float(ev.locate_s),
            "n_evaluated": 0 if ev is None else int(ev.n_evaluated), "n_scops": int(fit.n_scops)}


def _sweep_summary(sweeps: dict[str, list[Evaluation]]) -> dict[str, list[dict]]:
    return {name: [{"n_scops": int(e.n_scops), "rmse_px": _finite_or_none(e.rmse_px),
                    "dr_max_px": _finite_or_none(e.dr_max_px), "n_evaluated": int(e.n_evaluated)} for e in evs]
            for name, evs in sweeps.items()}


def _markdown_html(text: str) -> str:
    """The GUI's summary table (:func:`explorer.app.model.summary_markdown`: a pipe table, then ``- `` notes
    with ``**bold**`` names) as HTML."""
    import html
    import re

    out, rows = [], []
    for line in text.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if not all(set(c) <= {"-", ":"} for c in cells):
                rows.append(cells)
        elif line.startswith("- "):
            out.append("<li>" + re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", html.escape(line[2:])) + "</li>")
    table = ""
    if rows:
        head = "".join(f"<th>{html.escape(c)}</th>" for c in rows[0])
        body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows[1:])
        table = (f'<table border="1" cellpadding="4" style="border-collapse: collapse" id="summary-table">'
                 f"<tr>{head}</tr>{body}</table>")
    return table + (f"<ul>{''.join(out)}</ul>" if out else "")


def export_files(scene: Any, s: Settings, *, source: dict, seed: int = 0,
                 fits: dict[str, FitRecord] | None = None, stand_in: StandIn | None = None,
                 sweep_fit: Callable[[str, int], FitRecord | None] | None = None,
                 native_pixels: bool = False, workers: int = 1, early_pool: Any = None) -> dict[str, bytes]:
    """Compute the export of ``s`` on ``scene`` (every SCP) and return ``{file name: bytes}``.

    Parameters
    ----------
    scene : Sensor
        The sensor: the truth every residual is measured against (its own ``project``).
    s : Settings
        ``methods``, ``scop_density``, ``scp_count`` (and the MLP controls) are used.
    source : dict
        Written as ``summary.json["source"]``.
    seed : int
        Seed of the SCOP / SCP heights.
    fits : dict, optional
        Fits already made for these settings (the GUI's), by method; others are fitted here.
    sweep_fit : callable, optional
        ``sweep_fit(method, n_scops)``: a fit the GUI already made for the accuracy-vs-SCOPs sweep (same scene,
        seed and SCOPs), or None to fit it here.
    stand_in : StandIn, optional
        Its error against the sensor is written as ``summary.json["stand_in"]``, as ``residuals.csv`` rows of
        method :data:`STAND_IN_METHOD` and as a map beside the methods'.
    native_pixels : bool
        Add the camera's ``line, sample`` columns (a USGS CSM source).
    workers : int
        Processes for the accuracy-vs-SCOPs sweep: 2 or more starts a second process
        (:class:`explorer.app.sweep_pool.SweepPool`) that refits the learned methods at the other densities while
        this one computes the maps, then shares the rest; the files are the same bytes as with 1 (serial).
        Without ``sweep_fit`` only.
    early_pool : SweepPool, optional
        A pool started before the sensor was loaded (:meth:`~explorer.app.sweep_pool.SweepPool.early`; its worker
        has imported meanwhile): given the sweep's jobs here, or stopped when this export has none for it.
    """
    model = ExplorerModel(preview_after_s=None, seed=seed, scenes={s.preset: scene})
    pool = None
    if s.sweep and workers > 1 and sweep_fit is None:
        # the sweep's refits at the other densities start now on a second process, while the maps are computed here
        from explorer.app.sweep_pool import SweepPool

        jobs = _pool_jobs(model, s)
        if early_pool is not None:
            pool, early_pool = early_pool, None
            pool.submit(scene, s, seed, model.sweep_points, jobs)
        else:
            pool = SweepPool(scene, s, seed, model.sweep_points, jobs)
    if early_pool is not None:  # no sweep to share
        early_pool.close()
    try:
        return _export_files(model, pool, scene, s, source=source, seed=seed, fits=fits, stand_in=stand_in,
                             sweep_fit=sweep_fit, native_pixels=native_pixels)
    finally:
        if pool is not None:
            pool.close()


def _pool_jobs(model: ExplorerModel, s: Settings) -> list[tuple[str, int]]:
    """The sweep jobs a second process may take: every learned method's densities but the maps' own (whose fit
    the maps make anyway), the longest first (long trainings, then more SCOPs)."""
    from explorer.methods import registry

    reg = registry()
    jobs = [(name, d) for name in s.methods for d in model.sweep_densities(name)
            if reg[name].needs_fit and d != int(s.scop_density)]
    return sorted(jobs, key=lambda j: (not reg[j[0]].long_fit, -j[1]))


def _sweep_with_pool(model: ExplorerModel, pool: Any, s: Settings,
                     meanwhile: Callable[[], None] | None = None) -> tuple[dict[str, list[Evaluation]],
                                                                           dict[str, dict[int, str]]]:
    """The sweep of every method of ``s``, its jobs shared with ``pool``'s worker; the same evaluations, in the
    same order, as :meth:`ExplorerModel.sweep` method by method.  ``meanwhile()`` is called once every job is
    taken, before waiting for the worker's last results (work that does not depend on the sweep)."""
    from explorer.app.model import sweep_results

    def compute(name: str, density: int) -> tuple[str, Any]:
        return model.sweep_point(name, s, density, lambda d: model.fit(name, s, d, purpose=SWEEP_PURPOSE))

    done: dict[tuple[str, int], tuple[str, Any]] = {}
    shared = {job: k for k, job in enumerate(pool.jobs)}
    for name in s.methods:  # the jobs only this process does: the maps' density (fits cached) and fit-free methods
        for d in model.sweep_densities(name):
            if (name, d) not in shared:
                done[(name, d)] = compute(name, d)
    while (k := pool.claim()) is not None:
        done[pool.jobs[k]] = compute(*pool.jobs[k])
    if meanwhile is not None:
        meanwhile()
    for k, result in pool.collect().items():
        done[pool.jobs[k]] = result
    sweeps: dict[str, list[Evaluation]] = {}
    failed: dict[str, dict[int, str]] = {}
    for name in s.methods:
        failed[name] = {}
        points = []
        for d in model.sweep_densities(name):
            if (name, d) not in done:  # taken by the worker but never delivered: computed here
                done[(name, d)] = compute(name, d)
            points.append((d, done[(name, d)]))
        sweeps[name] = sweep_results(points, failed[name])
    return sweeps, failed


def _export_files(model: ExplorerModel, pool: Any, scene: Any, s: Settings, *, source: dict, seed: int,
                  fits: dict[str, FitRecord] | None, stand_in: StandIn | None,
                  sweep_fit: Callable[[str, int], FitRecord | None] | None,
                  native_pixels: bool) -> dict[str, bytes]:
    from explorer.app.model import MethodRun, summary_markdown
    from explorer.panels import figures as F  # noqa: N812

    scops = model.scops(s)
    scps = model.scps(s)  # re-projected by the sensor's own ground_to_image (sensor_truth), as in the GUI
    evaluations: dict[str, Evaluation] = {}
    status: dict[str, np.ndarray] = {}
    summary: dict[str, Any] = {}
    timing: dict[str, Any] = {}
    runs: dict[str, MethodRun] = {}
    for name in s.methods:
        rec = (fits or {}).get(name) or model.fit(name, s)
        # the GUI's own path (ExplorerModel.evaluate): every SCP, fit time and status included
        run = model.evaluate(name, s, fit=rec)
        runs[name] = run
        ev, st, err = run.evaluation, run.status, run.error or rec.error
        if ev is not None and st is not None:
            evaluations[name], status[name] = ev, st
        summary[name] = method_summary(ev, st, rec, err)
        timing[name] = method_timing(ev, rec)
    maps = dict(evaluations)
    map_status = dict(status)
    stand_in_summary: dict[str, Any] | None = None
    if stand_in is not None:
        ev_s, st_s = evaluate_stand_in(stand_in, scps, STAND_IN_METHOD)
        maps[STAND_IN_METHOD], map_status[STAND_IN_METHOD] = ev_s, st_s
        stand_in_summary = {"model": stand_in.label, "against": source.get("truth"),
                            **method_summary(ev_s, st_s, FitRecord(None, 0.0, 0, {}), None)}
        for k in ("n_scops", "ce_per_point", "warnings", "n_refused", "n_not_converged"):
            stand_in_summary.pop(k, None)
    # what does not depend on the sweep is made before it (with a second process, while it trains on)
    body_fixed = scene.frame.enu_to_ecef(scps.ground)
    residuals_csv_bytes = residuals_csv(maps, map_status, scps, body_fixed, native_pixels)
    map_figs: list[tuple] = []
    if maps:
        labels = {STAND_IN_METHOD: f"stand-in: {stand_in.label}"} if stand_in is not None else None
        map_figs.append((f"Residual maps (row and column; every check point, cell {s.aggregate})" + (
            "; the stand-in's error against the sensor beside the methods'" if stand_in is not None else ""),
            F.residual_maps(maps, scps, control=scops, shape=scene.shape, mode="per method",
                            component="row and column", status=map_status, aggregate=s.aggregate, labels=labels,
                            against=stand_in_truth(source))))
    # the GUI's accuracy-vs-SCOPs panel: the same sweep (ExplorerModel.sweep), fits at every density
    t_sweep = time.perf_counter()
    sweeps: dict[str, list[Evaluation]] = {}
    sweep_failed: dict[str, dict[int, str]] = {}
    if pool is not None:
        def render_maps() -> None:  # the maps' part of panels.html (the page's first figure) while the worker ends
            if map_figs:
                map_figs[0] = (map_figs[0][0], F.render_figure(map_figs[0][1], 0))

        sweeps, sweep_failed = _sweep_with_pool(model, pool, s, meanwhile=render_maps)
    for name in (s.methods if s.sweep and pool is None else ()):
        def get_fit(density: int, name: str = name) -> FitRecord:
            return (sweep_fit(name, density) if sweep_fit is not None else None) or model.fit(
                name, s, density, purpose=SWEEP_PURPOSE)

        sweep_failed[name] = {}
        sweeps[name] = model.sweep(name, s, get_fit=get_fit, failed=sweep_failed[name])
    sweep_failed = {k: v for k, v in sweep_failed.items() if v}
    sweep_s = time.perf_counter() - t_sweep
    settings = {"methods": list(s.methods), "scops": int(s.scop_density), "scops_used": len(scops),
                "scps": int(s.scp_count), "scps_used": len(scps), "seed": int(seed),
                "mlp_layers": int(s.mlp_layers), "mlp_neurons": int(s.mlp_neurons),
                "image_rows": int(scene.n_rows), "image_columns": int(scene.n_columns), "subsampled": False,
                "sweep_scps": int(model.sweep_points) if s.sweep else None}
    truth = {"model": source.get("truth", type(scene).__name__), "body": scene.body.to_dict(),
             "residuals": "estimated minus the sensor's own ground_to_image at each check point",
             "check_points": "simulated by the sensor's own image_to_ground on its terrain",
             "check_points_left_out": model.scp_note(s)}
    payload = {"source": source, "settings": settings, "truth": truth, "methods": summary,
               "accuracy_vs_scops": _sweep_summary(sweeps) if s.sweep else None,
               "accuracy_vs_scops_failed": ({k: [{"n_scops": int(d), "error": e} for d, e in sorted(v.items())]
                                             for k, v in sweep_failed.items()} if s.sweep else None),
               "stand_in": stand_in_summary, "run_dependent": dict(RUN_DEPENDENT)}
    timing_payload = {"methods": timing, "about": RUN_DEPENDENT[TIMING_JSON],
                      "sweep_s": float(sweep_s) if s.sweep else None,
                      "units": {"fit_s": "s", "eval_s": "s (ground to image of n_evaluated check points)",
                                "sweep_s": "s (the accuracy-vs-SCOPs sweep: its fits and evaluations, wall time after "
                                           "the maps; with a second process its refits begin during the maps)"}}
    timing_text = json.dumps(timing_payload, indent=1, sort_keys=True, allow_nan=False)
    files = {"summary.json": (json.dumps(payload, indent=1, sort_keys=True, allow_nan=False) + "\n").encode(),
             "residuals.csv": residuals_csv_bytes}
    colors = F.method_colors(list(s.methods))
    figs: list[tuple] = list(map_figs)
    if sweeps:
        figs.append((f"Accuracy vs SCOP density (each method refitted at every density, evaluated on "
                     f"{min(model.sweep_points, len(scps)):,} check points)",
                     F.accuracy_vs_density(sweeps, colors=colors, failed=sweep_failed)))
    if runs:
        figs.append(("Summary (every check point)", _markdown_html(summary_markdown(runs, len(scps)))))
    if evaluations:
        # the measured times are run-dependent: they come from timing.js, so this page stays byte-identical
        figs.append(("Timing (measured on this run: timing.json / timing.js beside this page)",
                     F.timing_bars(evaluations, colors=colors, deferred=True),
                     F.timing_fill_script(list(evaluations))))
    notes = [f"source: {source.get('label', '')}", f"truth: {truth['model']}",
             f"{len(scps):,} check points (SCPs), {len(scops):,} SCOPs, "
             f"seed {seed}; every method evaluated on every SCP (no subsample)."]
    if stand_in is not None:
        notes.append(f"stand-in: {stand_in.label} (its error against the sensor is the map named stand-in)")
    coverage = source.get("dem_coverage")
    if coverage:
        notes.append(f"DEM covers {100 * coverage['fraction']:.1f} % of the image; {coverage['note']}")
    if source.get("table_coverage"):
        notes.append(table_coverage_text(source["table_coverage"]))
    if source.get("validity_note"):
        notes.append(f"RPC file: {source['validity_note']}")
    if truth.get("check_points_left_out"):
        notes.append(truth["check_points_left_out"])
    notes.append(f"Every file of this export is the same on every run with the same settings except "
                 f"{TIMING_JSON} and {TIMING_JS} (the measured times).")
    files["panels.html"] = F.figures_html(figs, "pushbroom explorer export", notes, scripts=[TIMING_JS]).encode()
    files[TIMING_JSON] = (timing_text + "\n").encode()
    files[TIMING_JS] = (f"window.{F.TIMING_GLOBAL} = {timing_text};\n").encode()
    return files


def default_file_methods() -> list[str]:
    """Methods an export of a file source evaluates by default: every learned and generalized method (they
    need only ground / image pairs) and every search method that is exact (``exactness == "exact"``); the
    pixel-level and interpolated scanline walks are left to ``--methods`` (their cost grows with the image's
    rows)."""
    from explorer.methods import registry

    return [n for n, c in registry().items() if c.family != "search" or c.exactness == "exact"]


def run_export(source: Any, out_dir: str | Path, *, methods: list[str] | None = None, scops: int = 100,
               scps: int = 50_000, seed: int = 0, sweep: bool = True, log: Any = print,
               workers: int | None = None, early_pool: Any = None) -> dict[str, Path]:
    """``pushbroom explore ... --export DIR``: compute and write the export's files into ``out_dir``.

    Parameters
    ----------
    source : explorer.sources.Source
    out_dir : str or Path
        Created if missing.
    methods : list of str, optional
        Default: :data:`explorer.app.model.DEFAULT_METHODS` that are registered.
    scops, scps : int
        SCOP density and SCP count (seeded grids).
    seed : int
    sweep : bool
        Include the accuracy-vs-SCOPs sweep (the GUI's default; ``--no-sweep`` leaves it out).
    log : callable
        Progress lines.
    workers : int, optional
        Processes for the sweep (:func:`export_files`); default 2 when this process may use two CPUs, else 1.
    early_pool : SweepPool, optional
        The sweep's worker started before the source was loaded (:func:`early_sweep_pool`); closed here if unused.

    Returns
    -------
    dict of str to Path
        The written files.

    Raises
    ------
    InputError
        An unknown method, or a count < 1.
    """
    from explorer.app.model import DEFAULT_METHODS
    from explorer.errors import InputError
    from explorer.methods import available

    names = available()
    if not methods and source.scene is not None:  # a file: measure every method that answers exactly or learns
        methods = default_file_methods()
    methods = list(methods) if methods else [m for m in DEFAULT_METHODS if m in names]
    unknown = [m for m in methods if m not in names]
    if unknown:
        raise InputError(f"unknown method(s) {', '.join(unknown)}; available: {', '.join(names)}")
    if scops < 1 or scps < 1:
        raise InputError(f"--scops and --scps must be >= 1, got {scops} and {scps}")
    if source.scene is None:
        from explorer.presets import build_scene

        scene, label = build_scene(source.label), source.label
    else:
        scene, label = source.scene, source.label
    s = Settings(preset=label, scop_density=int(scops), scp_count=int(scps), methods=tuple(methods),
                 color_method=methods[0] if methods else None, sweep=bool(sweep))
    t0 = time.perf_counter()
    if workers is None:
        from explorer._threads import cpus_available

        workers = min(2, cpus_available())
    files = export_files(scene, s, source=source.to_dict(), seed=seed, stand_in=source.stand_in,
                         native_pixels=source.kind == "isd", workers=workers, early_pool=early_pool)
    out = Path(out_dir)
    # written as a whole (a temporary folder renamed into place, locked against concurrent writers): after a
    # failure, SIGTERM or a full disk the folder holds the previous complete export or nothing
    written = write_folder_atomic(out, files)
    sweep_s = json.loads(files[TIMING_JSON]).get("sweep_s")
    sweep_note = f"; the accuracy-vs-SCOPs sweep {sweep_s:.1f} s of it (--no-sweep leaves it out)" if sweep_s else ""
    log(f"pushbroom explore: exported {', '.join(files)} to {out} ({time.perf_counter() - t0:.1f} s{sweep_note})")
    return written


def early_sweep_pool(methods: list[str] | None, sweep: bool) -> Any:
    """The accuracy-vs-SCOPs sweep's worker process of ``explore --export``, started before the source is loaded so
    that it imports the package meanwhile (:meth:`SweepPool.early`); None without a
    sweep or a second CPU.  ``methods``: the user's, or None for the defaults (:func:`default_file_methods` of a
    file, :data:`~explorer.app.model.DEFAULT_METHODS` of a preset: both are named, the source is not loaded yet).
    Pass it to :func:`run_export`, and close it if the export is not reached."""
    from explorer._threads import cpus_available

    if not sweep or min(2, cpus_available()) < 2:
        return None
    from explorer.app.model import DEFAULT_METHODS
    from explorer.app.sweep_pool import SweepPool

    return SweepPool.early(list(methods) if methods else [*default_file_methods(), *DEFAULT_METHODS])


__all__ = ["CSV_COLUMNS", "RUN_DEPENDENT", "export_files", "method_summary", "method_timing", "residuals_csv",
           "run_export", "sensor_truth", "early_sweep_pool"]
