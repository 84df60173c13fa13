"""Export what the explorer's panels show: ``summary.json``, ``residuals.csv``, ``panels.html``.

``pushbroom explore <source> --export DIR`` (and the GUI's *Export* button, as a zip) fits
every chosen method on the SCOPs and evaluates it on **every** SCP -- never a subsample --
then writes

* ``summary.json`` -- ``{"source": {...}, "settings": {...}, "methods": {name: {"rmse_row_px",
  "rmse_col_px", "max_row_px", "max_col_px", "n_valid", "n_invalid", "n_refused",
  "n_not_converged", "n_outside_image", "ce_per_point", "fit_s", "eval_s", "error"}}}``;
* ``residuals.csv`` -- one row per check point per method: ``method, scp_index, row_px,
  col_px, row_residual_px, col_residual_px, status`` (exact image position of the SCP,
  estimated minus exact, empty where the method gave no answer; status as in
  :data:`explorer.app.model.STATUS_NAMES`);
* ``panels.html`` -- the residual maps (row and column, every point drawn) and the timing
  bars in one page that opens offline (plotly.js inlined, nothing loaded from the network).

Reproducible: the points are seeded grids, the fits and evaluations take no timing-dependent
decision (no time budget), and numbers are written with 17 significant digits, so two runs
with the same settings give byte-identical ``residuals.csv``; timings appear only in
``summary.json`` (``fit_s``, ``eval_s``) and the timing panel.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any, cast

import numpy as np

from explorer.app.model import STATUS_NAMES, ExplorerModel, FitRecord, Settings, _Recording, point_status
from explorer.evaluate import Evaluation, evaluate_method
from explorer.io_atomic import atomic_folder
from explorer.methods.base import BestScanlineMethod

CSV_COLUMNS = ("method", "scp_index", "row_px", "col_px", "row_residual_px", "col_residual_px", "status")


def _num(a: np.ndarray) -> np.ndarray:
    """17-significant-digit text of float64 values (round-trips exactly); '' for NaN."""
    out = np.char.mod("%.17g", np.asarray(a, dtype=np.float64))
    return np.where(np.isfinite(a), out, "")


def _finite_or_none(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def residuals_csv(evaluations: dict[str, Evaluation], status: dict[str, np.ndarray], scps: Any) -> bytes:
    """The CSV text (bytes, LF line ends) of every evaluated point of every method (vectorised)."""
    lines = [",".join(CSV_COLUMNS)]
    names = np.array(STATUS_NAMES)
    for name, ev in evaluations.items():
        idx = np.asarray(ev.evaluated_index)
        cols = [np.full(idx.size, name), idx.astype(str), _num(scps.row[idx]), _num(scps.col[idx]),
                _num(ev.residual_row), _num(ev.residual_col), names[status[name]]]
        block = cols[0]
        for c in cols[1:]:
            block = np.char.add(np.char.add(block, ","), c)
        lines.extend(block.tolist())
    return ("\n".join(lines) + "\n").encode()


def method_summary(ev: Evaluation | None, status: np.ndarray | None, fit: FitRecord, error: str | None) -> dict:
    """The JSON entry of one method (see the module docstring)."""
    if ev is None:
        return {"error": error or fit.error, "fit_s": fit.fit_s, "eval_s": None, "n_valid": 0, "n_invalid": 0}
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
        "n_scops": int(fit.n_scops), "ce_per_point": float(ev.ce_evals_per_point),
        "fit_s": float(fit.fit_s), "eval_s": float(ev.locate_s), "error": None,
        "warnings": list(fit.warnings),
    }


def export_files(scene: Any, s: Settings, *, source: dict, seed: int = 0,
                 fits: dict[str, FitRecord] | None = None) -> dict[str, bytes]:
    """Compute the export of ``s`` on ``scene`` (every SCP) and return ``{file name: bytes}``.

    Parameters
    ----------
    scene : Scene
    s : Settings
        ``methods``, ``scop_density``, ``scp_count`` (and the MLP controls) are used.
    source : dict
        Written as ``summary.json["source"]``.
    seed : int
        Seed of the SCOP / SCP heights.
    fits : dict, optional
        Fits already made for these settings (the GUI's), by method; others are fitted here.
    """
    from explorer.panels import figures as F  # noqa: N812

    model = ExplorerModel(locate_budget_s=None, seed=seed, scenes={s.preset: scene})
    scops, scps = model.scops(s), model.scps(s)
    evaluations: dict[str, Evaluation] = {}
    status: dict[str, np.ndarray] = {}
    summary: dict[str, Any] = {}
    for name in s.methods:
        rec = (fits or {}).get(name) or model.fit(name, s)
        ev: Evaluation | None = None
        st: np.ndarray | None = None
        err = rec.error
        if rec.method is not None:
            rec_m = _Recording(rec.method)
            try:
                ev = evaluate_method(cast(BestScanlineMethod, rec_m), scps, seed=seed, fit=False)
                st = point_status(rec_m.result)
            except Exception as exc:  # a failing method is reported, not fatal
                err = f"{type(exc).__name__}: {exc}"
        if ev is not None and st is not None:
            evaluations[name], status[name] = ev, st
        summary[name] = method_summary(ev, st, rec, err)
    settings = {"methods": list(s.methods), "scops": int(s.scop_density), "scops_used": len(scops),
                "scps": int(s.scp_count), "scps_used": len(scps), "seed": int(seed),
                "mlp_layers": int(s.mlp_layers), "mlp_neurons": int(s.mlp_neurons),
                "image_rows": int(scene.n_rows), "image_columns": int(scene.n_columns), "subsampled": False}
    payload = {"source": source, "settings": settings, "methods": summary}
    files = {"summary.json": (json.dumps(payload, indent=1, sort_keys=True, allow_nan=False) + "\n").encode(),
             "residuals.csv": residuals_csv(evaluations, status, scps)}
    figs = []
    if evaluations:
        figs.append(("Residual maps (row and column; every check point drawn)", F.residual_maps(
            evaluations, scps, control=scops, shape=scene.shape, mode="per method", component="row and column",
            status=status, max_points=None)))
        figs.append(("Timing", F.timing_bars(evaluations)))
    notes = [f"source: {source.get('label', '')}", f"{len(scps):,} check points (SCPs), {len(scops):,} SCOPs, "
             f"seed {seed}; every method evaluated on every SCP (no subsample)."]
    files["panels.html"] = F.figures_html(figs, "pushbroom explorer export", notes).encode()
    return files


def run_export(source: Any, out_dir: str | Path, *, methods: list[str] | None = None, scops: int = 100,
               scps: int = 50_000, seed: int = 0, log: Any = print) -> dict[str, Path]:
    """``pushbroom explore ... --export DIR``: compute and write the three files into ``out_dir``.

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
    log : callable
        Progress lines.

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
                 color_method=methods[0] if methods else None)
    t0 = time.perf_counter()
    files = export_files(scene, s, source=source.to_dict(), seed=seed)
    out = Path(out_dir)
    written = {}
    # written as a whole (a temporary folder renamed into place, locked against concurrent writers): after a
    # failure, SIGTERM or a full disk the folder holds the previous complete export or nothing
    with atomic_folder(out, tuple(files)) as tmp:
        for name, data in files.items():
            (tmp / name).write_bytes(data)
            written[name] = out / name
    log(f"pushbroom explore: exported {', '.join(files)} to {out} ({time.perf_counter() - t0:.1f} s)")
    return written


__all__ = ["CSV_COLUMNS", "export_files", "method_summary", "residuals_csv", "run_export"]
