"""Image-space best-scanline searches on integer scanlines: sequential search (SS), bisecting
window search (BWS) and their sub-pixel "interpolated" versions.

* ``ss`` -- sequential search: walk the scanlines one by one and stop where the along-track
  collinearity residual ``x`` changes sign; the best scanline is the integer row with the
  smaller ``|x|`` (Ahooei Nezhad, Valadan Zoej & Jannati 2020, section 2-2, Fig. 3).
* ``bws`` -- bisecting window search (Liu & Wang 2007, "Efficient orthoimage generation from
  ADS40 level 0 products", J. Remote Sensing 11(2):247; described in Ahooei Nezhad et al.
  2020, section 2-3, Figs. 4-5): halve the window ``[first, last]`` keeping the half whose end
  residuals differ in sign, until it holds at most ``final_window`` rows, then search it
  sequentially.
* ``ss-interp`` / ``bws-interp`` -- the improvement of Ahooei Nezhad et al. 2020 (eq. 4): take
  the two neighbouring integer rows ``t1, t2`` between which ``x`` changes sign and return the
  inverse-|x| weighted mean ``t = (t1/|x1| + t2/|x2|) / (1/|x1| + 1/|x2|)``, which is the
  linear interpolation of the root between the two lines (written here as
  ``(t1 |x2| + t2 |x1|) / (|x1| + |x2|)``, the same value without a division by zero).

Ahooei Nezhad, S.S., Valadan Zoej, M.J., Jannati, M. (2020): Accuracy improvement of best
scanline search algorithms for object to image transformation of linear pushbroom imagery,
J. Geospatial Information Technology 8(1):23-38 (in Persian).

Search window (all four methods): the integer rows ``-1, 0, ..., rows`` -- one line beyond each
end of the image, so that a root in the edge half-pixels ``[-0.5, 0)`` and ``(rows-1, rows-0.5]``
(which are on the image, ``docs/conventions.md#pixels``) is bracketed by two evaluated lines.
A point whose residual has no sign change over that window comes back with ``converged=False``
and ``row=NaN``; a root found in ``[-1, -0.5)`` or ``(rows-0.5, rows]`` gives a row off the
image, which the base class flags ``inside=False``.  Nothing is clipped or extrapolated.

Cost accounting: one evaluation of the residual for one point at one row is one collinearity
evaluation (CE).  The pixel-level methods take the column from the focal-plane ``y`` of the
evaluation at the chosen row (no extra CE); the interpolated methods compute the column by the
collinearity at the interpolated row (+1 CE, counted only for points that have a row).  The interpolation
itself needs no evaluation beyond the search: both bracketing lines were evaluated by it.

Conventions (rows, time, residual): ``docs/conventions.md``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from explorer.methods._common import changes_sign, residual_and_column_px, weighted_mean_row
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.scene import Scene

SELECT_CHOICES = ("nearest", "lower")


def _nan_row(n: int) -> np.ndarray:
    return np.full(n, np.nan)


class _Bracket:
    """Per-point bracketing lines found by a search (all arrays (N,))."""

    def __init__(self, n: int) -> None:
        self.lo = _nan_row(n)  # lower integer row t1
        self.f_lo = _nan_row(n)
        self.c_lo = _nan_row(n)
        self.f_hi = _nan_row(n)  # residual at t2 = lo + 1
        self.c_hi = _nan_row(n)
        self.found = np.zeros(n, dtype=bool)
        self.ce = np.zeros(n, dtype=np.int64)


def sequential_walk(
    scene: Scene,
    ground: np.ndarray,
    lo: np.ndarray,
    f_lo: np.ndarray,
    c_lo: np.ndarray,
    hi: np.ndarray,
    f_hi: np.ndarray | None,
    c_hi: np.ndarray | None,
    bracket: _Bracket,
    index: np.ndarray,
    trace: list[np.ndarray] | None,
) -> None:
    """Walk rows ``lo+1, lo+2, ...`` per point until the residual changes sign.

    Fills ``bracket`` at ``index`` with the pair of consecutive rows that brackets the root and
    adds the evaluations to ``bracket.ce``.  Vectorised: one loop iteration evaluates the next
    row of every point still walking; a point leaves the active set as soon as it is bracketed.

    Parameters
    ----------
    scene, ground : Scene, ndarray (M, 3)
        ``ground`` holds the points being walked (already selected by ``index``).
    lo, f_lo, c_lo : ndarray, shape (M,)
        Start row (already evaluated), its residual (px) and column.
    hi : ndarray, shape (M,)
        Last row of the walk.
    f_hi, c_hi : ndarray (M,) or None
        Residual/column at ``hi`` when already known (then ``hi`` itself is never evaluated and
        a sign change between ``lo`` and ``hi`` is guaranteed by the caller); ``None`` to
        evaluate ``hi`` like any other row (a point with no sign change up to ``hi`` is left
        ``found=False``).
    bracket : _Bracket
        Output for all N points.
    index : ndarray of int, shape (M,)
        Positions of the walked points in ``bracket``.
    trace : list or None
        Receives one (N,) array per step (rows evaluated, NaN elsewhere).
    """
    n_all = bracket.lo.shape[0]
    act = np.arange(index.size)  # positions (into the walked arrays) of the points still walking
    g, h = ground, hi.astype(np.float64)
    fh = f_hi
    ch = c_hi
    row_prev, f_prev, c_prev = lo.astype(np.float64), f_lo.copy(), c_lo.copy()

    def finish(sel: np.ndarray, f2: np.ndarray, c2: np.ndarray) -> None:
        dst = index[act[sel]]
        bracket.lo[dst] = row_prev[sel]
        bracket.f_lo[dst] = f_prev[sel]
        bracket.c_lo[dst] = c_prev[sel]
        bracket.f_hi[dst] = f2
        bracket.c_hi[dst] = c2
        bracket.found[dst] = True

    while act.size:
        cand = row_prev + 1.0
        if fh is not None and ch is not None:  # given together
            # points whose next row is the already-known end: bracket [hi - 1, hi] without a CE
            at_end = cand >= h
            if at_end.any():
                finish(at_end, fh[at_end], ch[at_end])
                keep = ~at_end
                act, g, h, fh, ch = act[keep], g[keep], h[keep], fh[keep], ch[keep]
                cand, row_prev, f_prev, c_prev = cand[keep], row_prev[keep], f_prev[keep], c_prev[keep]
                if not act.size:
                    break
        f, c = residual_and_column_px(scene, g, cand)
        bracket.ce[index[act]] += 1
        if trace is not None:
            tr = np.full(n_all, np.nan)
            tr[index[act]] = cand
            trace.append(tr)
        done = changes_sign(f_prev, f)
        if done.any():
            finish(done, f[done], c[done])
        # without a known end, a point that evaluated ``hi`` with no sign change is finished (not found)
        stop = done | (cand >= h)
        if stop.any():
            keep = ~stop
            act, g, h, cand, f, c = act[keep], g[keep], h[keep], cand[keep], f[keep], c[keep]
            if fh is not None and ch is not None:
                fh, ch = fh[keep], ch[keep]
        row_prev, f_prev, c_prev = cand, f, c


class _IntegerRowSearch(BestScanlineMethod):
    """Common part of SS / BWS and their interpolated versions (see the module docstring).

    Parameters
    ----------
    scene : Scene
    select : {"nearest", "lower"}
        Pixel-level methods only: which of the two bracketing rows to return.  ``"nearest"``
        (default, the paper's rule): the one with the smaller ``|x|``; ``"lower"``: always the
        lower one, i.e. truncation (RMSE 1/sqrt(3) = 0.577 px, dr_max 1 px: the BWS figures of
        Ahooei Nezhad et al. 2024, Tables 4, look like this rule).  Ignored by the interpolated
        methods.
    """

    chunk_points = 1_000_000  # the active-set loop keeps several (N,) arrays per iteration

    interpolate: ClassVar[bool] = False

    def __init__(self, scene: Scene, *, select: str = "nearest") -> None:
        if select not in SELECT_CHOICES:
            raise ValueError(f"select must be one of {SELECT_CHOICES}, got {select!r}")
        super().__init__(scene, select=select)
        self.select = select

    # window of integer rows searched (one line beyond each image end)
    @property
    def first_row(self) -> int:
        return -1

    @property
    def last_row(self) -> int:
        return int(self.scene.n_rows)

    def _bracket(self, ground: np.ndarray, trace: list[np.ndarray] | None, info: dict) -> _Bracket:
        raise NotImplementedError

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        tr: list[np.ndarray] | None = [] if trace else None
        info: dict = {"first_row": self.first_row, "last_row": self.last_row}
        b = self._bracket(ground, tr, info)
        n = ground.shape[0]
        row = _nan_row(n)
        ok = b.found
        a1 = np.abs(b.f_lo[ok])
        a2 = np.abs(b.f_hi[ok])
        info["bracket_lo"] = b.lo.copy()
        if self.interpolate:
            # eq. 4: t = (t1/|x1| + t2/|x2|) / (1/|x1| + 1/|x2|) = (t1 |x2| + t2 |x1|) / (|x1| + |x2|)
            row[ok] = weighted_mean_row(b.lo[ok], b.lo[ok] + 1.0, b.f_lo[ok], b.f_hi[ok])
            # column by the collinearity at the interpolated row: one more CE, only where a row exists
            col = _nan_row(n)
            col[ok] = self.scene.column_at_row(ground[ok], row[ok])
            b.ce[ok] += 1
            return self._result(ground, row, ok, b.ce, col=col, trace=tr, info=info)
        col = _nan_row(n)
        if self.select == "nearest":
            take_hi = a2 < a1
        else:
            take_hi = np.zeros(a1.shape, dtype=bool)
        row[ok] = b.lo[ok] + take_hi
        col[ok] = np.where(take_hi, b.c_hi[ok], b.c_lo[ok])
        return self._result(ground, row, ok, b.ce, col=col, trace=tr, info=info)


@register
class SequentialSearch(_IntegerRowSearch):
    """Sequential search (SS): evaluate every scanline from the first until ``x`` changes sign.

    Cost: a point whose exact row is ``r`` needs ``ceil(r) + 2`` CE (rows ``-1 .. ceil(r)``),
    about ``rows / 2`` on average over the image; a point with no sign change needs ``rows + 2``.
    Returns integer rows (the bracketing row with the smaller ``|x|``).  See the module docstring.

    Parameters
    ----------
    scene : Scene
    select : {"nearest", "lower"}
        See :class:`_IntegerRowSearch`.
    """

    name = "ss"
    label = "Sequential search (SS)"
    reference = (
        "Ahooei Nezhad, Valadan Zoej & Jannati (2020), J. Geospatial Information Technology 8(1), sec. 2-2"
    )
    exactness = "pixel"

    def _bracket(self, ground: np.ndarray, trace: list[np.ndarray] | None, info: dict) -> _Bracket:
        n = ground.shape[0]
        b = _Bracket(n)
        lo = np.full(n, float(self.first_row))
        f0, c0 = residual_and_column_px(self.scene, ground, lo)
        b.ce += 1
        if trace is not None:
            trace.append(lo.copy())
        hi = np.full(n, float(self.last_row))
        sequential_walk(self.scene, ground, lo, f0, c0, hi, None, None, b, np.arange(n), trace)
        return b


@register
class BisectingWindowSearch(_IntegerRowSearch):
    """Bisecting window search (BWS, Liu & Wang 2007).

    The window starts as the integer rows ``[-1, rows]``; the residual is evaluated at both ends
    (2 CE) -- no sign change means the point is not seen by the image (``converged=False``).
    Then, while the window holds more than ``final_window`` rows, the middle row
    ``(first + last) // 2`` is evaluated (1 CE: both ends are already known) and the half whose
    ends differ in sign is kept.  Finally the window is searched sequentially from its first row
    (at most ``final_window - 2`` CE; the last row is known).  Integer output: the bracketing row
    with the smaller ``|x|``.

    Parameters
    ----------
    scene : Scene
    final_window : int
        Stop halving when the window holds at most this many rows (>= 2), default 8.  The paper
        does not give the threshold; ``final_window=2`` (bisect down to adjacent lines)
        reproduces its CE counts (15 for a 6000-line SPOT scene).
    select : {"nearest", "lower"}
        See :class:`_IntegerRowSearch`.

    Notes
    -----
    With ``trace=True``, ``result.info["windows"]`` lists the window ``(first, last)`` per
    halving as (N, 2) arrays (NaN for finished points).
    """

    name = "bws"
    label = "Bisecting window search (BWS)"
    reference = (
        "Liu & Wang (2007), Efficient orthoimage generation from ADS40 level 0 products, "
        "J. Remote Sensing 11(2):247"
    )
    exactness = "pixel"

    def __init__(self, scene: Scene, *, final_window: int = 8, select: str = "nearest") -> None:
        if int(final_window) != final_window or final_window < 2:
            raise ValueError(f"final_window must be an integer >= 2, got {final_window!r}")
        super().__init__(scene, select=select)
        self.final_window = int(final_window)
        self.params["final_window"] = self.final_window

    def _bracket(self, ground: np.ndarray, trace: list[np.ndarray] | None, info: dict) -> _Bracket:
        scene = self.scene
        n = ground.shape[0]
        b = _Bracket(n)
        lo = np.full(n, float(self.first_row))
        hi = np.full(n, float(self.last_row))
        f_lo, c_lo = residual_and_column_px(scene, ground, lo)
        f_hi, c_hi = residual_and_column_px(scene, ground, hi)
        b.ce += 2
        windows: list[np.ndarray] | None = [] if trace is not None else None
        if trace is not None:
            trace.append(lo.copy())
            trace.append(hi.copy())
        ok = changes_sign(f_lo, f_hi)
        act = np.flatnonzero(ok)
        # halving: all points share the same window length up to one row, so the loop is short
        while act.size:
            if windows is not None:
                w = np.full((n, 2), np.nan)
                w[act, 0], w[act, 1] = lo[act], hi[act]
                windows.append(w)
            big = (hi[act] - lo[act] + 1.0) > self.final_window
            act = act[big]
            if not act.size:
                break
            mid = np.floor(0.5 * (lo[act] + hi[act]))
            f_mid, c_mid = residual_and_column_px(scene, ground[act], mid)
            b.ce[act] += 1
            if trace is not None:
                tr = np.full(n, np.nan)
                tr[act] = mid
                trace.append(tr)
            left = changes_sign(f_lo[act], f_mid)
            li, ri = act[left], act[~left]
            hi[li], f_hi[li], c_hi[li] = mid[left], f_mid[left], c_mid[left]
            lo[ri], f_lo[ri], c_lo[ri] = mid[~left], f_mid[~left], c_mid[~left]
        if windows is not None:
            info["windows"] = windows
        idx = np.flatnonzero(ok)
        sequential_walk(scene, ground[idx], lo[idx], f_lo[idx], c_lo[idx], hi[idx], f_hi[idx], c_hi[idx],
                        b, idx, trace)
        return b


@register
class SequentialSearchInterpolated(SequentialSearch):
    """SS followed by the sub-pixel interpolation of eq. 4 (Ahooei Nezhad et al. 2020).

    Same CE as ``ss`` plus one for the column at the interpolated row.  The interpolation is
    exact only if ``x(t)`` is linear over one line; its error is about
    ``|x''| / (8 |x'|)`` pixels at most (curvature of the residual over one line).
    """

    name = "ss-interp"
    label = "Sequential search + sub-pixel interpolation (SS, eq. 4)"
    reference = (
        "Ahooei Nezhad, Valadan Zoej & Jannati (2020), J. Geospatial Information Technology 8(1), eq. 4"
    )
    exactness = "approximate"
    interpolate: ClassVar[bool] = True


@register
class BisectingWindowSearchInterpolated(BisectingWindowSearch):
    """BWS followed by the sub-pixel interpolation of eq. 4 (Ahooei Nezhad et al. 2020).

    Same CE as ``bws`` plus one for the column at the interpolated row; parameters as ``bws``.
    """

    name = "bws-interp"
    label = "Bisecting window search + sub-pixel interpolation (BWS, eq. 4)"
    reference = (
        "Liu & Wang (2007); Ahooei Nezhad, Valadan Zoej & Jannati (2020), J. Geospatial "
        "Information Technology 8(1), eq. 4"
    )
    exactness = "approximate"
    interpolate: ClassVar[bool] = True
