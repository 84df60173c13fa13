"""Polynomial least squares on ground features, shared by the regression methods and the pair column model.

* :func:`monomial_exponents`, :func:`design_matrix`, :func:`qr_least_squares`: the full polynomial of a total
  degree in normalised (X, Y[, Z]) and its QR least-squares fit (``lrm``, ``prm``, ``ogp``, ``ann``).
* :class:`PairColumnModel`: the column of a ground point learned from ground / image pairs (SCOPs) alone, the
  *declared column model* of a row-only learned method on a sensor without line geometry (an RPC), where no
  collinearity can give the column at the predicted row (``BestScanlineMethod.column_source``).

Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

from itertools import product

import numpy as np

from explorer.geometry.kernels import NUMBA_AVAILABLE
from explorer.methods._compiled import polynomial_predict
from explorer.methods._lm import GroundFeatures
from explorer.points import PointSet

CHUNK = 1 << 17  # points per block of design-matrix evaluation

#: Highest total degree of :class:`PairColumnModel`, and the least number of SCOPs per coefficient it asks for
#: before taking a degree (fewer: a lower degree; the same rule of "two equations per unknown" as the networks).
COLUMN_MAX_DEGREE = 3
COLUMN_POINTS_PER_COEFFICIENT = 2


def monomial_exponents(n_vars: int, degree: int) -> np.ndarray:
    """Exponents (P, n_vars) of all monomials of total degree <= ``degree``.

    Ordered by total degree, then lexicographically descending (1, x, y, z, x^2, xy, ...).
    """
    if degree < 0:
        raise ValueError(f"degree must be >= 0, got {degree}")
    terms = [e for e in product(range(degree + 1), repeat=n_vars) if sum(e) <= degree]
    terms.sort(key=lambda e: (sum(e), tuple(-v for v in e)))
    return np.array(terms, dtype=np.int64).reshape(-1, n_vars)


def design_matrix(features: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Monomials of normalised features.

    Parameters
    ----------
    features : ndarray, shape (N, D)
    exponents : ndarray, shape (P, D)

    Returns
    -------
    ndarray, shape (N, P)
    """
    n, d = features.shape
    max_deg = int(exponents.max()) if exponents.size else 0
    cols = np.ascontiguousarray(features.T)  # (D, N): each variable contiguous
    powers = [np.ones((d, n)), cols]
    for _ in range(2, max_deg + 1):
        powers.append(powers[-1] * cols)
    out = np.empty((exponents.shape[0], n))  # built term by term, returned transposed
    for j, e in enumerate(exponents):
        nz = np.flatnonzero(e)
        if nz.size == 0:
            out[j] = 1.0
            continue
        np.copyto(out[j], powers[e[nz[0]]][nz[0]])
        for v in nz[1:]:
            out[j] *= powers[e[v]][v]
    return out.T


def qr_least_squares(design: np.ndarray, target: np.ndarray, name: str) -> tuple[np.ndarray, float]:
    """Least-squares coefficients by Householder QR, and the design's 2-norm condition number.

    Raises ``ValueError`` when the design is rank deficient (degenerate SCOP layout).
    """
    # here, not at the module's top: scipy (its array-API layer) is ~0.2 s of CPU to import, and every process
    # importing the method registry imported it, also those that never fit a polynomial (the export's sweep worker)
    from scipy.linalg import solve_triangular

    q, r = np.linalg.qr(design, mode="reduced")
    diag = np.abs(np.diag(r))
    if diag.min() <= 1e-12 * diag.max():
        raise ValueError(
            f"{name}: the control points do not determine the {design.shape[1]} coefficients "
            "(rank-deficient design: points collinear or clustered)"
        )
    coef = solve_triangular(r, q.T @ target)
    return coef, float(np.linalg.cond(r))


def height_degree(control: PointSet) -> int:
    """Highest power of Z the column model takes from SCOPs at ``k`` distinct heights (to the mm): ``k - 1``, at
    most 2 (a DEM: heights everywhere, 2).  Monomials in Z up to the power ``k - 1`` are independent on ``k``
    layers; a higher one is aliased with them there (Z^3 on 3 layers is a combination of 1, Z, Z^2 at the layers),
    so the least squares fit it to the layers and let it bend freely between them: a cubic column model on a
    Pleiades RPC's 3-layer SCOPs was 2.8e-9 px off at the layers and 3 px off 18 m from the middle one (at most
    Z^2: 1.4e-6 px).  The column's height dependence is the relief parallax, linear in Z to (Z / orbit height)^2."""
    k = np.unique(np.round(control.ground[:, 2], 3)).size
    return int(min(2, max(k - 1, 1)))


class PairColumnModel:
    """The column of ground points as a polynomial of their normalised (X, Y[, Z]) fitted on SCOPs.

    The declared column model of a learned method that predicts only the row, on a sensor without line
    geometry (an RPC: there is no collinearity to give the column at the row).  The degree is the highest of
    3, 2, 1 whose coefficient count leaves at least :data:`COLUMN_POINTS_PER_COEFFICIENT` control points per
    coefficient (with Z as a feature when the SCOPs' heights span more than 1 m, as the regression methods, and at
    most the power of Z :func:`height_degree` allows).
    Exact for a column that is a polynomial of that degree in the ground coordinates; its training residuals
    are reported in :meth:`info`.

    Parameters
    ----------
    control : PointSet
        SCOPs (ground, col).
    name : str
        The method's name, for errors.

    Raises
    ------
    ValueError
        Fewer control points than an affine model has coefficients, or a degenerate layout.
    """

    def __init__(self, control: PointSet, name: str) -> None:
        # no domain refusal here: the method's own row model decides where it answers
        self.features = GroundFeatures(control, None, np.inf, np.inf)
        d = self.features.n_features
        self.height_degree = height_degree(control) if self.features.use_height else 0
        degrees = [k for k in range(COLUMN_MAX_DEGREE, 0, -1)
                   if COLUMN_POINTS_PER_COEFFICIENT * self._exponents(d, k).shape[0] <= len(control)]
        self.degree = degrees[0] if degrees else 1
        self.exponents = self._exponents(d, self.degree)
        if len(control) < self.exponents.shape[0]:
            raise ValueError(f"{name}: the column model from the pairs needs at least {self.exponents.shape[0]} "
                             f"control points, got {len(control)}")
        f, _ = self.features(control.ground)
        a = design_matrix(f, self.exponents)
        self.coef, self.condition_number = qr_least_squares(a, control.col, f"{name} (column model)")
        res = a @ self.coef - control.col
        self.train_rmse_px = float(np.sqrt(np.mean(res**2)))
        self.train_max_px = float(np.max(np.abs(res)))

    def _exponents(self, n_features: int, degree: int) -> np.ndarray:
        """Monomials of total degree <= ``degree`` whose power of Z is at most :attr:`height_degree`."""
        e = monomial_exponents(n_features, degree)
        return e[e[:, 2] <= self.height_degree] if n_features == 3 else e

    def __call__(self, ground: np.ndarray) -> np.ndarray:
        """Columns (N,) of ground points (N, 3), local ENU metres (0 collinearity evaluations)."""
        if NUMBA_AVAILABLE:
            values, _ = polynomial_predict(self.features, ground, self.exponents, self.coef[:, None])
            return values[0]
        f, _ = self.features(ground)
        out = np.empty(f.shape[0])
        for s in range(0, f.shape[0], CHUNK):
            out[s:s + CHUNK] = design_matrix(f[s:s + CHUNK], self.exponents) @ self.coef
        return out

    def info(self) -> dict:
        """JSON-ready description: what the column is, its degree, features and training residuals."""
        return {"source": "polynomial of the ground coordinates fitted on the SCOPs (the sensor has no line "
                          "geometry to give the column at the row)",
                "degree": self.degree, "use_height": self.features.use_height, "height_degree": self.height_degree,
                "n_coefficients": int(self.exponents.shape[0]), "train_rmse_px": self.train_rmse_px,
                "train_max_px": self.train_max_px}


__all__ = ["CHUNK", "COLUMN_MAX_DEGREE", "COLUMN_POINTS_PER_COEFFICIENT", "PairColumnModel", "design_matrix",
           "height_degree", "monomial_exponents", "qr_least_squares"]
