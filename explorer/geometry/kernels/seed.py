"""The polynomial row seed of :func:`explorer.geometry.kernels.solve_exact` (:class:`SeedModel`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit
from explorer.geometry.kernels.evaluators import _inlined_when_compiled, _table_index

# --------------------------------------------------------------------------- seeds
SEED_TERMS = 20  # cubic seed polynomial; lower degrees are zero-padded


@_inlined_when_compiled
def _seed_row_py(X, Y, Z, mean, inv_scale, coef):
    """Polynomial seed row in normalised ``(X - mean) * inv_scale``: ``coef`` (20,) multiplies the
    monomials of :func:`seed_features` (degree 3; lower degrees zero-padded), nested Horner-style.

    Scalars (compiled) or arrays (the numpy fallback), same operations.
    """
    u = (X - mean[0]) * inv_scale[0]
    v = (Y - mean[1]) * inv_scale[1]
    w = (Z - mean[2]) * inv_scale[2]
    c = coef
    ru = (
        c[1]
        + u * (c[4] + u * c[10] + v * c[11] + w * c[12])
        + v * (c[5] + v * c[13] + w * c[14])
        + w * (c[6] + w * c[15])
    )
    rv = c[2] + v * (c[7] + v * c[16] + w * c[17]) + w * (c[8] + w * c[18])
    rw = c[3] + w * (c[9] + w * c[19])
    return c[0] + (u * ru + (v * rv + w * rw))


def _seed_full_py(X, Y, Z, mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half):
    """Seed row: the polynomial plus, when ``len(cs) > 1``, a correction ``H`` (K, 3) tabulated over
    the polynomial's rows at three columns (linear interpolation in the row, quadratic Lagrange in the
    column given by the column polynomial ``ccoef``; see :class:`SeedModel`).  Scalars or arrays."""
    r = _seed_row_py(X, Y, Z, mean, inv_scale, coef)
    if len(cs) > 1:
        x = (r - c_r0) * c_inv
        k = _table_index(x, H.shape[0] - 2)
        f = x - k
        u = (_seed_row_py(X, Y, Z, mean, inv_scale, ccoef) - c_mid) * c_inv_half
        h0 = H[k, 0] + f * (H[k + 1, 0] - H[k, 0])
        h1 = H[k, 1] + f * (H[k + 1, 1] - H[k, 1])
        h2 = H[k, 2] + f * (H[k + 1, 2] - H[k, 2])
        r = r + (h1 + u * (0.5 * (h2 - h0) + u * (0.5 * (h0 + h2) - h1)))
    return r


_seed_full: Any = njit(cache=True, fastmath=False, inline="always")(_seed_full_py) if NUMBA_AVAILABLE else None


@dataclass(frozen=True)
class SeedModel:
    """The seed of :func:`solve_exact`: a polynomial ``row(X, Y, Z)`` in normalised coordinates plus an
    optional correction tabulated over rows (for time-only disturbances such as attitude jitter,
    which no low-degree polynomial of the ground coordinates follows).

    Attributes
    ----------
    mean, scale : ndarray, shape (3,)
        Normalisation ``(P - mean) / scale``.
    coef : ndarray, shape (4|10|20,)
        Coefficients over :func:`seed_features`.
    correction : ndarray, shape (K, 3) or (K,), or None
        Row correction at polynomial rows ``correction_row0 + k * correction_step`` and at the
        columns ``column_mid - column_half``, ``column_mid``, ``column_mid + column_half`` (one
        column: the same correction everywhere), added to the polynomial: linear interpolation at
        the polynomial's row, quadratic Lagrange interpolation at the column polynomial's column.
    correction_row0, correction_step : float
    column_coef : ndarray, shape (4|10|20,) or None
        Polynomial ``col(X, Y, Z)`` over :func:`seed_features` (needed with a 3-column correction).
    column_mid, column_half : float
    """

    mean: np.ndarray
    scale: np.ndarray
    coef: np.ndarray
    correction: np.ndarray | None = None
    correction_row0: float = 0.0
    correction_step: float = 1.0
    column_coef: np.ndarray | None = None
    column_mid: float = 0.0
    column_half: float = 1.0

    def args(self) -> tuple:
        """``(mean, inv_scale, coef (20,), cs, c_r0, c_inv, H (K, 3), ccoef (20,), c_mid, c_inv_half)``."""

        def pad(c: np.ndarray | None) -> np.ndarray:
            c = np.zeros(0) if c is None else np.asarray(c, dtype=np.float64)
            return np.concatenate([c, np.zeros(SEED_TERMS - len(c))])

        cs: tuple[int, ...]
        if self.correction is None:
            cs, H = (0,), np.zeros((2, 3))
        else:
            H = np.asarray(self.correction, dtype=np.float64)
            H = np.ascontiguousarray(np.repeat(H[:, None], 3, axis=1) if H.ndim == 1 else H)
            if H.shape[1] != 3 or H.shape[0] < 2:
                raise ValueError(f"seed correction must have shape (K >= 2, 3) or (K,), got {H.shape}")
            if not np.allclose(H[:, 0], H[:, 1]) and self.column_coef is None:
                raise ValueError("a seed correction that varies with the column needs column_coef")
            cs = (0, 0)
        return (
            np.asarray(self.mean, dtype=np.float64),
            1.0 / np.asarray(self.scale, dtype=np.float64),
            pad(self.coef),
            cs,
            float(self.correction_row0),
            1.0 / float(self.correction_step),
            H,
            pad(self.column_coef),
            float(self.column_mid),
            1.0 / float(self.column_half),
        )

    def rows(self, ground: np.ndarray) -> np.ndarray:
        """Seed rows (N,) of ground points (N, 3) (numpy; the kernels compute the same)."""
        return _seed_full_py(ground[:, 0], ground[:, 1], ground[:, 2], *self.args())


def seed_features(uvw: np.ndarray, degree: int) -> np.ndarray:
    """Monomials of normalised coordinates (N, 3) in the order :func:`_seed_row_py` uses: (N, 4|10|20)."""
    if degree not in (1, 2, 3):
        raise ValueError(f"seed degree must be 1, 2 or 3, got {degree}")
    u, v, w = uvw[:, 0], uvw[:, 1], uvw[:, 2]
    cols = [np.ones_like(u), u, v, w]
    if degree >= 2:
        cols += [u * u, u * v, u * w, v * v, v * w, w * w]
    if degree >= 3:
        cols += [
            u * u * u,
            u * u * v,
            u * u * w,
            u * v * v,
            u * v * w,
            u * w * w,
            v * v * v,
            v * v * w,
            v * w * w,
            w * w * w,
        ]
    return np.stack(cols, axis=1)
