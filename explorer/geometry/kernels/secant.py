"""The usgscsm production solver: secant iteration on the along-track residual (:func:`solve_secant`),
compiled per point, with its numpy fallback."""

from __future__ import annotations

import numpy as np

from explorer._numba import njit, prange
from explorer.geometry.kernels.evaluators import _ce_fixed, _ce_fixed_py, _collinearity_point_py, collinearity_point
from explorer.geometry.kernels.exact import _dummy_fixed
from explorer.geometry.kernels.params import CollinearityParams, FixedModel
from explorer.geometry.kernels.residual import _use_numba


# --------------------------------------------------------------------------- usgscsm secant solver
@njit(parallel=True, fastmath=False, cache=True)
def _solve_secant_nb(
    ground, proj, gx, fx, use_fixed, f_lo, f_hi, focal, offset, pitch, pc, line_period, ref_row, r_min, r_max,
    precision, first_step, max_count, row_out, col_out, ok_out, ce_out, trace,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    pos, dpos, att, datt, jit, _, _, curv, dist, sc0, fast = gx
    n = ground.shape[0]
    n_trace = trace.shape[0]
    for i in prange(n):
        X, Y, Z = ground[i, 0], ground[i, 1], ground[i, 2]
        # projective approximation (usgscsm computeProjectiveApproximation), clamped to the image
        u = (X - proj[8]) / proj[11]
        v = (Y - proj[9]) / proj[12]
        w = (Z - proj[10]) / proj[13]
        den = 1.0 + proj[4] * u + proj[5] * v + proj[6] * w
        approx = (proj[0] + proj[1] * u + proj[2] * v + proj[3] * w) / den
        if den == 0.0 or not np.isfinite(approx):
            approx = 0.5 * (r_min + r_max)
        if approx < r_min:
            approx = r_min
        if approx > r_max:
            approx = r_max
        # usgscsm: e0 = e(0); e1 = e(0.1); while |e1| > precision and ++count < max_count:
        #   if e1 == e0 break; t2 = t1 - e1 (t1 - t0) / (e1 - e0); shift.  Then the column at t1.
        # Written with one evaluation site (phase 0, 1: the probes; 2: secant steps; 3: column).
        t0 = 0.0
        t1 = 0.0
        e0 = 0.0
        e1 = 0.0
        ts = 0.0
        phase = 0
        count = 0
        ce = 0
        valid = True
        col = np.nan
        while True:
            rowq = approx + ts
            t = (rowq - ref_row) * line_period
            if use_fixed and f_lo <= rowq <= f_hi:
                e, _, yd, _, vz = _ce_fixed(
                    X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal,
                    offset,
                )
            else:
                e, _, yd, _, vz = collinearity_point(
                    X, Y, Z, t, pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast
                )
            ce += 1
            valid = valid and vz < 0.0
            if phase == 3:
                col = yd / pitch + pc
                break
            if ce - 1 < n_trace:
                trace[ce - 1, i] = rowq
            e = e / pitch
            if phase == 0:
                t0 = ts
                e0 = e
                ts = first_step
                phase = 1
                continue
            if phase == 1:
                t1 = ts
                e1 = e
                phase = 2
            else:
                t0 = t1
                e0 = e1
                t1 = ts
                e1 = e
            if abs(e1) > precision:
                count += 1
                if count < max_count and e1 != e0:
                    ts = t1 - e1 * (t1 - t0) / (e1 - e0)
                    continue
            ts = t1
            phase = 3
        row = approx + t1
        row_out[i] = row
        col_out[i] = col
        ok_out[i] = valid and (abs(e1) <= precision) and np.isfinite(row)
        ce_out[i] = ce


def _line_error_np(ground, row, p: CollinearityParams, fm: FixedModel | None, f_lo, f_hi, fast):
    """Numpy twin of :func:`_line_error` on arrays (same evaluator choice per point)."""
    t = (row - p.reference_row) * p.line_period
    out = [np.empty(row.shape) for _ in range(5)]
    in_fixed = (f_lo <= row) & (row <= f_hi) if fm is not None else np.zeros(row.shape, bool)
    for mask, fixed in ((in_fixed, True), (~in_fixed, False)):
        if not mask.any():
            continue
        if fixed and fm is not None:  # in_fixed is all False without a fixed model
            res = _ce_fixed_py(
                ground[mask, 0], ground[mask, 1], ground[mask, 2], t[mask], *fm.args(), p.focal, p.offset
            )
        else:
            res = _collinearity_point_py(
                ground[mask, 0], ground[mask, 1], ground[mask, 2], t[mask], *p.model_args(fast)
            )
        for o, v in zip(out, res, strict=True):
            o[mask] = v
    return out


def _solve_secant_np(
    ground,
    proj,
    p: CollinearityParams,
    fm, f_lo, f_hi, fast, r_min, r_max, precision, first_step, max_count, trace_rows,
):
    """Vectorised numpy twin of :func:`_solve_secant_nb` (same iteration, same decisions)."""
    n = ground.shape[0]
    u = (ground[:, 0] - proj[8]) / proj[11]
    v = (ground[:, 1] - proj[9]) / proj[12]
    w = (ground[:, 2] - proj[10]) / proj[13]
    den = 1.0 + proj[4] * u + proj[5] * v + proj[6] * w
    with np.errstate(divide="ignore", invalid="ignore"):
        approx = (proj[0] + proj[1] * u + proj[2] * v + proj[3] * w) / den
    approx = np.where((den == 0.0) | ~np.isfinite(approx), 0.5 * (r_min + r_max), approx)
    approx = np.clip(approx, r_min, r_max)

    def err(idx, t_off):
        with np.errstate(divide="ignore", invalid="ignore"):
            e, _, yd, _, vz = _line_error_np(ground[idx], approx[idx] + t_off, p, fm, f_lo, f_hi, fast)
        return e / p.pitch, yd, vz

    everything = np.arange(n)
    t0 = np.zeros(n)
    e0, _, vz0 = err(everything, t0)
    t1 = np.full(n, first_step)
    e1, _, vz1 = err(everything, t1)
    ce = np.full(n, 2, np.int64)
    valid = (vz0 < 0.0) & (vz1 < 0.0)
    if trace_rows.shape[0] > 0:
        trace_rows[0] = approx + t0
    if trace_rows.shape[0] > 1:
        trace_rows[1] = approx + t1
    count = np.zeros(n, np.int64)
    active = everything[np.abs(e1) > precision]
    while active.size:
        count[active] += 1
        keep = (count[active] < max_count) & (e1[active] != e0[active])
        active = active[keep]
        if active.size == 0:
            break
        a0, a1, f0, f1 = t0[active], t1[active], e0[active], e1[active]
        t2 = a1 - f1 * (a1 - a0) / (f1 - f0)
        e2, _, vz2 = err(active, t2)
        ce[active] += 1
        valid[active] &= vz2 < 0.0
        k = ce[active] - 1
        tr = k < trace_rows.shape[0]
        trace_rows[k[tr], active[tr]] = approx[active[tr]] + t2[tr]
        t0[active], e0[active] = a1, f1
        t1[active], e1[active] = t2, e2
        active = active[np.abs(e2) > precision]
    row = approx + t1
    _, yd, vz_f = err(everything, t1)
    ce += 1
    col = yd / p.pitch + p.principal_column
    ok = valid & (vz_f < 0.0) & (np.abs(e1) <= precision) & np.isfinite(row)
    return row, col, ok, ce


FIXED_MARGIN_ROWS = 64.0  # the secant's fixed evaluator covers the image +- this many rows


def solve_secant(
    params: CollinearityParams,
    ground: np.ndarray,
    proj: np.ndarray,
    *,
    precision: float,
    first_step: float = 0.1,
    max_count: int = 15,
    trace: bool = False,
    backend: str = "auto",
    fast: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray] | None]:
    """The usgscsm line-scan ``groundToImage`` secant iteration, per point.

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
    proj : ndarray, shape (14,)
        ``(a0..a3, b1..b3, unused, mean x, y, z, scale x, y, z)``: projective line seed
        ``(a0 + a.u) / (1 + b.u)`` in normalised ground coordinates ``u``.
    precision : float
        Stop when the detector-line residual ``|x_d - x_det| / pitch`` is at most this (pixels).
    first_step : float
        Second probe, rows after the seed (usgscsm: 0.1).
    max_count : int
        usgscsm's iteration limit (15).
    trace : bool
    backend : {"auto", "numba", "numpy"}
    fast : bool
        Fast evaluators (default; the fixed one inside the image +-64 rows where the scene fits,
        else the general fast one), equal to the reference to round-off; False: the reference.

    Returns
    -------
    row, col : ndarray (N,)
    ok : ndarray of bool (N,)
        Residual precision met (usgscsm would warn PRECISION_NOT_MET otherwise), in front of the camera.
    ce : ndarray of int64 (N,)
        Collinearity evaluations per point, the final column evaluation included.
    trace : list of ndarray (N,) or None
    """
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    proj = np.ascontiguousarray(proj, dtype=np.float64)
    p = params
    n = ground.shape[0]
    r_min, r_max = -0.5, p.n_rows - 0.5
    f_lo, f_hi = r_min - FIXED_MARGIN_ROWS, r_max + FIXED_MARGIN_ROWS
    fm = p.fixed_model((f_lo, f_hi)) if fast else None
    trace_rows = np.full((max_count + 2 if trace else 0, n), np.nan)
    if _use_numba(backend):
        f = fm if fm is not None else _dummy_fixed()
        row, col = np.empty(n), np.empty(n)
        ok = np.empty(n, np.bool_)
        ce = np.empty(n, np.int64)
        _solve_secant_nb(
            ground,
            proj,
            p.model_args(fast),
            f.args(),
            fm is not None,
            f_lo,
            f_hi,
            p.focal,
            p.offset,
            p.pitch,
            p.principal_column,
            p.line_period,
            p.reference_row,
            r_min,
            r_max,
            float(precision),
            float(first_step),
            int(max_count),
            row, col, ok, ce, trace_rows,
        )
    else:
        row, col, ok, ce = _solve_secant_np(
            ground, proj, p, fm, f_lo, f_hi, fast, r_min, r_max,
            float(precision),
            float(first_step),
            int(max_count),
            trace_rows,
        )
    out_trace = None
    if trace:
        used = int((ce - 1).max()) if n else 0
        out_trace = [trace_rows[k].copy() for k in range(used)]
    return row, params.to_columns(col), ok, ce, out_trace
