"""Independent truth for tests: a brute-force bracketing best-scanline solver.

It scans every integer row (plus a margin) for a sign change of the along-track
residual and bisects the bracket to machine precision.  Slow and simple on purpose:
it shares no code with the methods under test beyond the collinearity residual.
"""

from __future__ import annotations

import numpy as np


def brute_force_rows(scene, ground: np.ndarray, margin: int = 50, iterations: int = 200) -> np.ndarray:
    """Exact fractional rows (N,) of ground points (N, 3); NaN where no sign change exists."""
    ground = np.asarray(ground, dtype=np.float64)
    n = ground.shape[0]
    rows = np.arange(-margin, scene.n_rows + margin, dtype=np.float64)
    f = np.empty((rows.size, n))
    for k, r in enumerate(rows):
        f[k] = scene.along_track_residual(ground, np.full(n, scene.scanline_time(r)))
    change = np.sign(f[:-1]) != np.sign(f[1:])
    has = change.any(axis=0)
    k = np.argmax(change, axis=0)
    lo = rows[k].copy()
    hi = lo + 1.0
    flo = f[k, np.arange(n)]
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        fm = scene.along_track_residual(ground, scene.scanline_time(mid))
        same = np.sign(fm) == np.sign(flo)
        lo = np.where(same, mid, lo)
        flo = np.where(same, fm, flo)
        hi = np.where(same, hi, mid)
        if np.all(hi - lo < 1e-13):
            break
    out = 0.5 * (lo + hi)
    out[~has] = np.nan
    return out
