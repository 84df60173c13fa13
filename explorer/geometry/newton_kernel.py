"""The safeguarded Newton-Raphson best-scanline iteration of ``nr``, compiled per point.

The same iteration as the vectorised numpy loop of :class:`explorer.methods.newton.NewtonRaphson`
(Chen & Rau 1993; Ahooei Nezhad, Valadan Zoej & Jannati 2020, eq. 3): every point starts at one
row, takes Newton steps on the along-track residual ``f(row)`` (pixels) with its analytic
derivative, keeps a bracket ``[lo, hi]`` that each evaluation shrinks (the residual is monotone in
time), sends a step that leaves the bracket to the unevaluated bracket end or bisects, bisects
after a step that did not reduce ``|f|``, and stops when the Newton step is below ``tol`` rows.
Here the whole iteration of one point runs inside one numba ``prange`` loop (no Python per
iteration, no active-set bookkeeping), with the collinearity evaluation of
:mod:`explorer.geometry.kernels` inlined: the branch-free evaluator where the scene fits it, the
general one otherwise.  Decisions are those of the numpy loop; the residuals differ from it only by
round-off (about 1e-10 px), so the returned rows agree to that.

Conventions: ``docs/conventions.md#best-scanline``.
"""

from __future__ import annotations

import numpy as np

from explorer.geometry.kernels import (
    NUMBA_AVAILABLE,
    CollinearityParams,
    _ce_either,
    _dummy_fixed,
    njit,
    prange,
)


@njit(parallel=True, fastmath=False, cache=True)
def _newton_raphson_nb(
    ground, start, gx, fx, use_fixed, pitch, pc, line_period, ref_row, lo0, hi0, tol, max_iter, row_out, col_out,
    converged_out, ce_out,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    scale_f = 1.0 / pitch
    scale_d = line_period / pitch
    for i in prange(ground.shape[0]):
        X, Y, Z = ground[i, 0], ground[i, 1], ground[i, 2]
        r = start
        lo = lo0
        hi = hi0
        lo_known = False
        hi_known = False
        f_prev = np.inf
        row = np.nan
        col = np.nan
        converged = False
        ce = 0
        for _ in range(max_iter):
            t = (r - ref_row) * line_period
            g, gt, yd, _ydt, _vz = _ce_either(
                X, Y, Z, t, use_fixed, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, gx
            )
            ce += 1
            f = g * scale_f
            fd = gt * scale_d
            col = yd * scale_f + pc
            row = r  # best estimate so far (kept for max_iter failures)
            below = f * fd > 0.0
            exact = f == 0.0
            if below:
                hi = r
                hi_known = True
            elif not exact:
                lo = r
                lo_known = True
            outside = (not exact) and lo >= hi
            fd_ok = np.isfinite(fd) and fd != 0.0
            step = f / fd if fd_ok else np.inf
            t_newton = r - step
            if (exact or abs(step) < tol) and not outside:
                row = r if exact else t_newton
                converged = True
                break
            if outside:
                row = np.nan
                col = np.nan
                break
            mid = 0.5 * (lo + hi)
            slow = abs(f) >= f_prev
            if slow or not fd_ok:
                r_next = mid
            elif not (t_newton > lo):
                r_next = mid if lo_known else lo
            elif not (t_newton < hi):
                r_next = mid if hi_known else hi
            else:
                r_next = t_newton
            f_prev = abs(f)
            r = r_next
        row_out[i] = row
        col_out[i] = col
        converged_out[i] = converged
        ce_out[i] = ce


def solve_newton_raphson(
    params: CollinearityParams,
    ground: np.ndarray,
    *,
    start_row: float,
    bracket: tuple[float, float],
    tol: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Safeguarded Newton-Raphson from one start row for every point, compiled (numba).

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
        Local ENU metres (finite; validated by the caller).
    start_row : float
        Initial row of every point (inside ``bracket``).
    bracket : (float, float)
        Lowest and highest row searched.
    tol : float
        Stop when the Newton step is below this many rows.
    max_iter : int
        Evaluations per point.

    Returns
    -------
    row, col : ndarray, shape (N,)
        NaN where the root lies beyond an evaluated bracket end; the last iterate (row) after
        ``max_iter`` evaluations without convergence.
    converged : ndarray of bool, shape (N,)
    ce : ndarray of int64, shape (N,)
        Collinearity evaluations per point (one per iteration).

    Raises
    ------
    RuntimeError
        Without numba (the caller falls back to its numpy loop).
    """
    if not NUMBA_AVAILABLE:
        raise RuntimeError("the compiled Newton-Raphson kernel needs numba")
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    p = params
    lo0, hi0 = float(bracket[0]), float(bracket[1])
    fm = p.fixed_model((lo0, hi0))
    f = fm if fm is not None else _dummy_fixed()
    n = ground.shape[0]
    row, col = np.empty(n), np.empty(n)
    converged = np.empty(n, dtype=np.bool_)
    ce = np.empty(n, dtype=np.int64)
    _newton_raphson_nb(
        ground, float(start_row), p.model_args(True), f.args(), fm is not None, p.pitch,
        p.principal_column, p.line_period, p.reference_row, lo0, hi0, float(tol), int(max_iter),
        row, col, converged, ce,
    )
    return row, p.to_columns(col), converged, ce
