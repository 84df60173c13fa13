"""Seeded, safeguarded Newton on the along-track residual per point (:func:`solve_exact`): compiled
branch-free Newton passes, then a per-point bracketed iteration; numpy fallback with the same decisions."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explorer._numba import njit, prange
from explorer.geometry.kernels.evaluators import _ce_either, _ce_fixed, _ce_fixed_py, _collinearity_point_py
from explorer.geometry.kernels.params import (
    STATUS_CONVERGED,
    STATUS_INVALID,
    STATUS_MAX_ITER,
    STATUS_NO_ROOT_IN_WINDOW,
    CollinearityParams,
    FixedModel,
    store_point,
)
from explorer.geometry.kernels.residual import _use_numba
from explorer.geometry.kernels.seed import SeedModel, _seed_full

# --------------------------------------------------------------------------- exact: vectorised Newton passes
_RUNNING, _ACCEPTED, _TO_GENERAL, _NO_ROOT = 0, 1, 2, 3


@njit(cache=True, fastmath=False, inline="always")
def _newton_update(
    i, rr, g, gt, yd, ydt, vz, line_period, pitch, pc, w_lo, w_hi, orient, accept_step, r, row_out, col_out, state
):  # pragma: no cover - compiled
    gr = gt * line_period
    delta = -g / gr
    rn = rr + delta
    good = (vz < 0.0) & (orient * gr > 0.0) & (abs(delta) < np.inf)
    outward = ((rr >= w_hi) & (delta > 0.0)) | ((rr <= w_lo) & (delta < 0.0))
    acc = good & (abs(delta) <= accept_step)
    row_out[i] = rn
    col_out[i] = (yd + ydt * line_period * delta) / pitch + pc
    r[i] = rn if good else rr
    state[i] = _ACCEPTED if acc else (_NO_ROOT if (good & outward) else (_RUNNING if good else _TO_GENERAL))


def _newton_update_np(rr, g, gt, yd, ydt, vz, line_period, pitch, pc, w_lo, w_hi, orient, accept_step):
    """Numpy twin of :func:`_newton_update` (same operations): (row, col, next r, state)."""
    gr = gt * line_period
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = -g / gr
    rn = rr + delta
    good = (vz < 0.0) & (orient * gr > 0.0) & (np.abs(delta) < np.inf)
    outward = ((rr >= w_hi) & (delta > 0.0)) | ((rr <= w_lo) & (delta < 0.0))
    acc = good & (np.abs(delta) <= accept_step)
    state = np.where(acc, _ACCEPTED, np.where(good & outward, _NO_ROOT, np.where(good, _RUNNING, _TO_GENERAL)))
    return rn, (yd + ydt * line_period * delta) / pitch + pc, np.where(good, rn, rr), state.astype(np.int8)


@njit(parallel=True, fastmath=False, cache=True)
def _newton_pass_nb(
    ground, idx, sx, fx, focal, offset, pitch, pc, line_period, ref_row, w_lo, w_hi, orient, accept_step, k, steps, r,
    row_out, col_out, state, ce, trace,
):  # pragma: no cover - compiled
    """One compiled Newton pass: ``len(steps)`` unconditional evaluations per point (rows clipped to the window).

    ``k == 0`` (the first pass): every point, starting from the seed; else the points ``idx``, from ``r``,
    ``k`` evaluations into their iteration (their trace rows and CE counts continue from there).
    """
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half = sx
    n_trace = trace.shape[0]
    from_seed = k == 0
    m = ground.shape[0] if from_seed else idx.shape[0]
    for j in prange(m):
        i = np.int64(j) if from_seed else idx[j]
        X, Y, Z = ground[i, 0], ground[i, 1], ground[i, 2]
        for s in range(len(steps)):  # 1 or 2 unconditional Newton evaluations (unrolled)
            if s == 0 and from_seed:
                rr = _seed_full(X, Y, Z, mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half)
            else:
                rr = r[i]
            rr = min(max(rr, w_lo), w_hi)
            if n_trace > k + s:
                trace[k + s, i] = rr
            t = (rr - ref_row) * line_period
            g, gt, yd, ydt, vz = _ce_fixed(
                X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset
            )
            _newton_update(
                i, rr, g, gt, yd, ydt, vz, line_period, pitch, pc, w_lo, w_hi, orient, accept_step, r, row_out, col_out,
                state,
            )
        ce[i] = k + len(steps)


_EVERY_POINT = np.zeros(0, np.int64)  # the (unused) index array of the first pass, which takes every point


# --------------------------------------------------------------------------- exact: safeguarded iteration
@njit(parallel=True, fastmath=False, cache=True)
def _solve_exact_nb(
    ground, start, gx, fx, use_fixed, pitch, pc, line_period, ref_row, w_lo, w_hi, orient, tol, accept_step,
    max_iter, row_out, col_out, status_out, ce_out, trace,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    n = ground.shape[0]
    n_trace = trace.shape[0]
    for i in prange(n):
        X, Y, Z = ground[i, 0], ground[i, 1], ground[i, 2]
        r = start[i]
        if not (r >= w_lo):  # also catches NaN
            r = w_lo if r < w_lo else 0.5 * (w_lo + w_hi)
        if r > w_hi:
            r = w_hi
        lo = w_lo
        hi = w_hi
        lo_eval = False
        hi_eval = False
        prev_abs = np.inf
        last_newton = False
        status = STATUS_MAX_ITER
        row = np.nan
        col = np.nan
        ce = 0
        for it in range(max_iter):
            if it < n_trace:
                trace[it, i] = r
            t = (r - ref_row) * line_period
            g, gt, yd, ydt, vz = _ce_either(
                X, Y, Z, t, use_fixed, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, gx
            )
            ce += 1
            if not (vz < 0.0) or not np.isfinite(g) or not np.isfinite(gt):
                status = STATUS_INVALID
                break
            gr = gt * line_period
            ydr = ydt * line_period
            sg = orient * g
            if sg == 0.0:
                row = r
                col = yd / pitch + pc
                status = STATUS_CONVERGED
                break
            if sg > 0.0:  # the root lies below r
                hi = r
                hi_eval = True
                if r <= w_lo:
                    status = STATUS_NO_ROOT_IN_WINDOW
                    break
            else:
                lo = r
                lo_eval = True
                if r >= w_hi:
                    status = STATUS_NO_ROOT_IN_WINDOW
                    break
            newton_ok = orient * gr > 0.0
            rn = r
            if newton_ok:
                delta = -g / gr
                if abs(delta) <= accept_step:
                    row = r + delta
                    col = (yd + ydr * delta) / pitch + pc
                    status = STATUS_CONVERGED
                    break
                rn = r + delta
                if last_newton and abs(g) > 0.5 * prev_abs:
                    newton_ok = False
            if newton_ok and lo < rn < hi:
                last_newton = True
            else:
                last_newton = False
                if newton_ok and rn <= lo and not lo_eval:
                    rn = w_lo
                elif newton_ok and rn >= hi and not hi_eval:
                    rn = w_hi
                else:
                    rn = 0.5 * (lo + hi)
                    if lo_eval and hi_eval and hi - lo <= tol + 1e-15 * abs(hi):
                        row = rn
                        col = (yd + ydr * (rn - r)) / pitch + pc
                        status = STATUS_CONVERGED
                        break
            prev_abs = abs(g)
            r = rn
        store_point(i, status, STATUS_CONVERGED, row, col, ce, row_out, col_out, status_out, ce_out)


def _evaluate_np(ground, t, p: CollinearityParams, fm: FixedModel | None, fast: bool):
    """One CE on arrays with the evaluator the solvers use (fixed model if given, else general)."""
    if fm is not None:
        return _ce_fixed_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *fm.args(), p.focal, p.offset)
    return _collinearity_point_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *p.model_args(fast))


def _solve_exact_np(
    ground,
    start,
    p: CollinearityParams,
    fm: FixedModel | None,
    fast: bool,
    w_lo, w_hi, orient, tol, accept_step, max_iter, trace_rows,
):
    """Vectorised numpy twin of :func:`_solve_exact_nb` (same algorithm, same decisions)."""
    n = ground.shape[0]
    r = np.asarray(start, dtype=np.float64).copy()
    r = np.where(np.isnan(r), 0.5 * (w_lo + w_hi), np.clip(r, w_lo, w_hi))
    lo = np.full(n, w_lo)
    hi = np.full(n, w_hi)
    lo_eval = np.zeros(n, bool)
    hi_eval = np.zeros(n, bool)
    prev_abs = np.full(n, np.inf)
    last_newton = np.zeros(n, bool)
    status = np.full(n, STATUS_MAX_ITER, np.int8)
    row = np.full(n, np.nan)
    col = np.full(n, np.nan)
    ce = np.zeros(n, np.int64)
    active = np.arange(n)
    dt = p.line_period
    pc = p.principal_column
    for it in range(max_iter):
        if active.size == 0:
            break
        ra = r[active]
        if it < trace_rows.shape[0]:
            trace_rows[it, active] = ra
        t = (ra - p.reference_row) * dt
        with np.errstate(divide="ignore", invalid="ignore"):
            g, gt, yd, ydt, vz = _evaluate_np(ground[active], t, p, fm, fast)
        ce[active] += 1
        gr = gt * dt
        ydr = ydt * dt
        m = active.size
        done = np.zeros(m, bool)
        new_status = np.full(m, STATUS_MAX_ITER, np.int8)
        new_row = np.full(m, np.nan)
        new_col = np.full(m, np.nan)

        def finish(mask, st, rr=None, cc=None, done=done, new_status=new_status, new_row=new_row, new_col=new_col):
            mask = mask & ~done
            new_status[mask] = st
            if rr is not None:
                new_row[mask] = rr[mask]
                new_col[mask] = cc[mask]
            done[mask] = True

        finish(~(vz < 0.0) | ~np.isfinite(g) | ~np.isfinite(gt), STATUS_INVALID)
        sg = orient * g
        finish(sg == 0.0, STATUS_CONVERGED, ra, yd / p.pitch + pc)
        above = (sg > 0.0) & ~done
        below = (sg < 0.0) & ~done
        hi_a = np.where(above, ra, hi[active])
        lo_a = np.where(below, ra, lo[active])
        hie = hi_eval[active] | above
        loe = lo_eval[active] | below
        finish(above & (ra <= w_lo), STATUS_NO_ROOT_IN_WINDOW)
        finish(below & (ra >= w_hi), STATUS_NO_ROOT_IN_WINDOW)
        newton_ok = (orient * gr > 0.0) & ~done
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = np.where(newton_ok, -g / gr, 0.0)
        finish(
            newton_ok & (np.abs(delta) <= accept_step), STATUS_CONVERGED, ra + delta, (yd + ydr * delta) / p.pitch + pc
        )
        rn = np.where(newton_ok, ra + delta, ra)
        newton_ok &= ~done & ~(last_newton[active] & (np.abs(g) > 0.5 * prev_abs[active]))
        take = newton_ok & (lo_a < rn) & (rn < hi_a)
        probe_lo = ~take & newton_ok & (rn <= lo_a) & ~loe
        probe_hi = ~take & newton_ok & (rn >= hi_a) & ~hie & ~probe_lo
        bis = ~take & ~probe_lo & ~probe_hi
        mid = 0.5 * (lo_a + hi_a)
        rn = np.where(probe_lo, w_lo, np.where(probe_hi, w_hi, np.where(bis, mid, rn)))
        tiny = bis & loe & hie & (hi_a - lo_a <= tol + 1e-15 * np.abs(hi_a))
        finish(tiny, STATUS_CONVERGED, mid, (yd + ydr * (mid - ra)) / p.pitch + pc)
        lo[active] = lo_a
        hi[active] = hi_a
        lo_eval[active] = loe
        hi_eval[active] = hie
        last_newton[active] = take
        prev_abs[active] = np.abs(g)
        r[active] = rn
        fin = active[done]
        status[fin] = new_status[done]
        row[fin] = new_row[done]
        col[fin] = new_col[done]
        active = active[~done]
    return row, col, status, ce


def _dummy_fixed() -> FixedModel:
    """A placeholder of the right types for kernels told not to use the fixed evaluator."""
    z = np.zeros(1)
    return FixedModel(
        np.zeros((3, 4)),
        np.zeros((3, 3)),
        np.zeros((3, 4)),
        np.zeros((3, 3)),
        np.zeros((3, 2)),
        (0,),
        np.zeros((0, 5)),
        z,
        np.zeros((0, 1)),
        np.zeros((0, 1)),
        0.0,
        1.0,
        (0,),
        z,
        (0,),
        z,
    )


@dataclass(frozen=True)
class NewtonOptions:
    """The search settings of :func:`solve_exact` and :func:`explorer.geometry.torch_solver.solve_exact_torch`
    (their keyword arguments), checked and converted once.

    Parameters
    ----------
    window : (float, float)
        Search window in rows; roots outside it are reported as ``STATUS_NO_ROOT_IN_WINDOW``.
    orient : float
        +1 if the residual increases with the row, -1 otherwise (a property of the scene).
    tol : float
        Target row error (also the bisection bracket width that counts as converged).
    accept_step : float
        Newton steps below this many rows are accepted (with the step applied); chosen so that
        the quadratic error of the step is below ``tol``.
    max_iter : int
        Evaluations per point in the safeguarded iteration.
    max_fast_passes : int
        Plain Newton evaluations per point before the safeguarded iteration takes over.
    first_evaluations : {1, 2}
        Newton evaluations every point gets in the first compiled pass, unconditionally (2 when
        the seed is known to be too coarse for one: it saves a pass over the points).

    Raises
    ------
    ValueError
        ``first_evaluations`` other than 1 or 2.
    """

    window: tuple[float, float]
    orient: float
    tol: float
    accept_step: float
    max_iter: int
    max_fast_passes: int = 8
    first_evaluations: int = 1

    def __post_init__(self) -> None:
        if int(self.first_evaluations) not in (1, 2):
            raise ValueError(f"first_evaluations must be 1 or 2, got {self.first_evaluations}")
        converted = {"window": (float(self.window[0]), float(self.window[1])), "orient": float(self.orient),
                     "tol": float(self.tol), "accept_step": float(self.accept_step), "max_iter": int(self.max_iter),
                     "max_fast_passes": int(self.max_fast_passes), "first_evaluations": int(self.first_evaluations)}
        for name, value in converted.items():
            object.__setattr__(self, name, value)


def solve_exact(
    params: CollinearityParams,
    ground: np.ndarray,
    seed: SeedModel,
    *,
    trace: bool = False,
    backend: str = "auto",
    fast: bool = True,
    **options: Any,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray] | None]:
    """Seeded Newton on the along-track residual with a safeguarded fallback, per point.

    Where the scene fits the branch-free evaluator (:meth:`CollinearityParams.fixed_model`) and
    ``fast`` is set, up to ``max_fast_passes`` plain Newton passes run first, each one compiled
    loop over the points still unresolved (vectorised by LLVM): pass 1 starts from the
    window-clipped seed; a point is accepted when its Newton step is at most ``accept_step`` rows
    (the step is applied), declared rootless when it sits on a window end and the step points
    outward (the residual is monotone), and handed to the safeguarded iteration when the
    evaluation is unusable (behind the camera, derivative of the wrong sign).  The safeguarded
    iteration (per-point bracket, bisection, window probes) finishes every point left, starting
    from its last iterate.

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
    seed : SeedModel
        Polynomial row seed (plus optional row correction table).
    trace : bool
        Return the rows visited per evaluation (NaN once a point has finished).
    backend : {"auto", "numba", "numpy"}
    fast : bool
        Fast evaluators (default; equal to the reference to round-off) or the bitwise reference
        evaluator (safeguarded iteration only).
    **options
        ``window, orient, tol, accept_step, max_iter`` and optionally ``max_fast_passes,
        first_evaluations``: see :class:`NewtonOptions`.

    Returns
    -------
    row, col : ndarray, shape (N,)
        NaN where not converged.
    status : ndarray of int8, shape (N,)
    ce : ndarray of int64, shape (N,)
        Collinearity evaluations per point (each gives residual, derivative and column).
    trace : list of ndarray (N,) or None
    """
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    sx = seed.args()
    n = ground.shape[0]
    o = NewtonOptions(**options)
    (w_lo, w_hi), orient, tol, accept_step = o.window, o.orient, o.tol, o.accept_step
    max_iter, max_fast_passes, first = o.max_iter, o.max_fast_passes, o.first_evaluations
    p = params
    use_nb = _use_numba(backend)
    fm = p.fixed_model(o.window) if fast else None
    dt, ref, pitch, pc = p.line_period, p.reference_row, p.pitch, p.principal_column
    n_trace = (max_fast_passes + max_iter) if trace else 0
    trace_rows = np.full((n_trace, n), np.nan)
    row = np.empty(n)  # every entry is written below
    col = np.empty(n)
    status = np.zeros(n, np.int8)  # STATUS_CONVERGED
    if fm is not None and max_fast_passes >= first:
        r = np.empty(n)
        state = np.empty(n, np.int8)
        if use_nb:
            ce = np.empty(n, np.int64)
            _newton_pass_nb(
                ground, _EVERY_POINT, sx, fm.args(), p.focal, p.offset, pitch, pc, dt, ref, w_lo, w_hi, orient,
                accept_step, 0, (0,) * first, r, row, col, state, ce, trace_rows,
            )
        else:
            ce = np.full(n, first, np.int64)
            rr = np.minimum(np.maximum(seed.rows(ground), w_lo), w_hi)
            for step in range(first):
                if step > 0:
                    rr = np.minimum(np.maximum(r, w_lo), w_hi)
                if trace:
                    trace_rows[step] = rr
                with np.errstate(divide="ignore", invalid="ignore"):
                    g, gt, yd, ydt, vz = _ce_fixed_py(
                        ground[:, 0], ground[:, 1], ground[:, 2], (rr - ref) * dt, *fm.args(), p.focal, p.offset
                    )
                row, col, r, state = _newton_update_np(
                    rr, g, gt, yd, ydt, vz, dt, pitch, pc, w_lo, w_hi, orient, accept_step
                )
        pending = np.flatnonzero(state != _ACCEPTED)  # usually empty or small; one pass over int8
        idx = pending[state[pending] == _RUNNING]
        k = first
        while idx.size and k < max_fast_passes:
            if use_nb:
                _newton_pass_nb(
                    ground, idx, sx, fm.args(), p.focal, p.offset, pitch, pc, dt, ref, w_lo, w_hi, orient,
                    accept_step, k, (0,), r, row, col, state, ce, trace_rows,
                )
            else:
                rr = np.minimum(np.maximum(r[idx], w_lo), w_hi)
                if trace:
                    trace_rows[k, idx] = rr
                with np.errstate(divide="ignore", invalid="ignore"):
                    g, gt, yd, ydt, vz = _ce_fixed_py(
                        ground[idx, 0], ground[idx, 1], ground[idx, 2], (rr - ref) * dt, *fm.args(), p.focal, p.offset
                    )
                row[idx], col[idx], r[idx], state[idx] = _newton_update_np(
                    rr, g, gt, yd, ydt, vz, dt, pitch, pc, w_lo, w_hi, orient, accept_step
                )
                ce[idx] = k + 1
            k += 1
            idx = idx[state[idx] == _RUNNING]
        final = state[pending]
        no_root = pending[final == _NO_ROOT]
        status[no_root] = STATUS_NO_ROOT_IN_WINDOW
        row[no_root] = np.nan
        col[no_root] = np.nan
        rest = pending[(final == _RUNNING) | (final == _TO_GENERAL)]
        start = r[rest]
    else:
        ce = np.zeros(n, np.int64)
        rest = np.arange(n)
        start = seed.rows(ground)
    if rest.size:
        sub = ground[rest]
        offsets = ce[rest]
        sub_trace = np.full((max_iter if trace else 0, rest.size), np.nan)
        if use_nb:
            f = fm if fm is not None else _dummy_fixed()
            r2, c2 = np.empty(rest.size), np.empty(rest.size)
            s2 = np.empty(rest.size, np.int8)
            ce2 = np.empty(rest.size, np.int64)
            _solve_exact_nb(
                sub,
                np.ascontiguousarray(start),
                p.model_args(fast),
                f.args(),
                fm is not None,
                pitch, pc, dt, ref, w_lo, w_hi, orient, tol, accept_step,
                int(max_iter),
                r2, c2, s2, ce2, sub_trace,
            )
        else:
            r2, c2, s2, ce2 = _solve_exact_np(
                sub, start, p, fm, fast, w_lo, w_hi, orient, tol, accept_step, int(max_iter), sub_trace
            )
        row[rest] = r2
        col[rest] = c2
        status[rest] = s2
        ce[rest] += ce2
        if trace:
            for off in np.unique(offsets):
                sel = offsets == off
                trace_rows[off : off + max_iter, rest[sel]] = sub_trace[:, sel][: n_trace - off]
    out_trace = None
    if trace:
        used = int(ce.max()) if n else 0
        out_trace = [trace_rows[k].copy() for k in range(used)]
    return row, p.to_columns(col), status, ce, out_trace
