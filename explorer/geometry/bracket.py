"""Ground -> image for any collinearity model by bracketing the best-scanline condition.

The along-track residual ``g(row)`` of a ground point (``docs/conventions.md#best-scanline``) changes
sign at its best scanline.  :func:`bracket_best_scanline` samples it over the image (plus a margin),
then refines the sign change by the Illinois variant of regula falsi (Dowell & Jarratt, "A modified
regula falsi method for computing the root of an equation", 1971).  It needs nothing but the residual,
so it serves every model (MPC polynomials, interpolated ephemeris and attitude) and is independent of
the best-scanline methods under study; vectorised over points, one Python step per iteration.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from explorer.errors import as_points


class CollinearityModel(Protocol):
    """What :func:`bracket_best_scanline` needs of a model (e.g. :class:`explorer.scene.Scene`)."""

    @property
    def n_rows(self) -> int: ...

    def scanline_time(self, row: np.ndarray) -> np.ndarray: ...

    def along_track_residual(self, ground: np.ndarray, t: np.ndarray) -> np.ndarray: ...

    def column_at_row(self, ground: np.ndarray, row: np.ndarray) -> np.ndarray: ...


def bracket_best_scanline(
    model: CollinearityModel,
    ground: np.ndarray,
    *,
    row_guess: np.ndarray | None = None,
    margin_fraction: float = 0.25,
    n_bracket: int = 33,
    tol_rows: float = 1e-10,
    max_iter: int = 100,
    guess_halfwidth_rows: float | np.ndarray = 2.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground -> image for any model: solve the best-scanline condition by bracketing.

    The along-track residual is sampled at ``n_bracket`` rows spanning the image plus
    ``margin_fraction`` of its height on each side (or, with ``row_guess``, at the guess +-
    ``guess_halfwidth_rows`` first); the sign change is refined by the Illinois variant of regula falsi until the
    bracket is below ``tol_rows``.

    Parameters
    ----------
    model : CollinearityModel
        A scene (``n_rows``, ``scanline_time``, ``along_track_residual``, ``column_at_row``).
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    row_guess : ndarray, shape (N,), optional
        Approximate rows (e.g. from an RPC); speeds up the bracket.
    margin_fraction, n_bracket, tol_rows, max_iter
        Search window margin (fraction of the image height), samples of the first bracket,
        bracket width that counts as converged (rows), iterations.
    guess_halfwidth_rows : float or ndarray, shape (N,)
        The first bracket about ``row_guess`` (default +-2 rows; a point whose residual does not change sign
        within it is searched over the whole window).

    Returns
    -------
    row, col : ndarray, shape (N,)
        Fractional image coordinates (0-based, pixel centre); NaN where no root was bracketed.
    converged : ndarray of bool, shape (N,)
    """
    ground = as_points(ground)
    n = ground.shape[0]

    def f(rows: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return model.along_track_residual(ground[idx], model.scanline_time(rows))

    lo = np.full(n, np.nan)
    hi = np.full(n, np.nan)
    flo = np.full(n, np.nan)
    fhi = np.full(n, np.nan)
    todo = np.arange(n)
    if row_guess is not None:
        g = np.asarray(row_guess, dtype=np.float64)
        ok = np.isfinite(g)
        idx = todo[ok]
        hw = np.broadcast_to(np.asarray(guess_halfwidth_rows, dtype=np.float64), g.shape)[ok]
        a, b = g[ok] - hw, g[ok] + hw
        fa, fb = f(a, idx), f(b, idx)
        good = np.sign(fa) != np.sign(fb)
        lo[idx[good]], hi[idx[good]] = a[good], b[good]
        flo[idx[good]], fhi[idx[good]] = fa[good], fb[good]
        todo = np.setdiff1d(todo, idx[good])
    if todo.size:
        margin = margin_fraction * model.n_rows
        grid = np.linspace(-margin, model.n_rows - 1 + margin, n_bracket)
        vals = np.stack([f(np.full(todo.size, r), todo) for r in grid])  # (K, m)
        change = np.sign(vals[:-1]) != np.sign(vals[1:])
        has = change.any(axis=0)
        k = np.argmax(change, axis=0)
        cols = np.arange(todo.size)
        sel = todo[has]
        lo[sel], hi[sel] = grid[k[has]], grid[k[has] + 1]
        flo[sel], fhi[sel] = vals[k[has], cols[has]], vals[k[has] + 1, cols[has]]
    active = np.flatnonzero(np.isfinite(lo))
    converged = np.zeros(n, dtype=bool)
    side = np.zeros(n, dtype=np.int8)
    for _ in range(max_iter):
        if active.size == 0:
            break
        a, b, fa, fb = lo[active], hi[active], flo[active], fhi[active]
        with np.errstate(divide="ignore", invalid="ignore"):
            m = (a * fb - b * fa) / (fb - fa)
        bad = ~np.isfinite(m) | (m <= np.minimum(a, b)) | (m >= np.maximum(a, b))
        m = np.where(bad, 0.5 * (a + b), m)
        fm = f(m, active)
        left = np.sign(fm) == np.sign(fa)  # root in [m, b]
        new_lo = np.where(left, m, a)
        new_hi = np.where(left, b, m)
        new_flo = np.where(left, fm, fa)
        new_fhi = np.where(left, fb, fm)
        # Illinois: halve the function value of the end point that stayed twice in a row
        s = side[active]
        new_fhi = np.where(left & (s == 1), 0.5 * new_fhi, new_fhi)
        new_flo = np.where(~left & (s == -1), 0.5 * new_flo, new_flo)
        side[active] = np.where(left, 1, -1)
        lo[active], hi[active], flo[active], fhi[active] = new_lo, new_hi, new_flo, new_fhi
        done = (np.abs(new_hi - new_lo) < tol_rows) | (fm == 0)
        converged[active[done]] = True
        lo[active[fm == 0]] = m[fm == 0]
        hi[active[fm == 0]] = m[fm == 0]
        active = active[~done]
    row = np.where(converged, 0.5 * (lo + hi), np.nan)
    col = np.full(n, np.nan)
    if converged.any():
        col[converged] = model.column_at_row(ground[converged], row[converged])
    return row, col, converged
