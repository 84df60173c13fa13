"""Best scanline by regression on simulated control points: ``lrm`` and ``prm``.

Ahooei Nezhad, Valadan Zoej, Youssefi, Ghaderpour (2024), "A Linear Regression
Approach for Best Scanline Determination in the Object to Image Space
Transformation Using Pushbroom Images", Sensors 24:5594, sections 2.3.2-2.3.4:
the row (scanline) of a ground point is a linear (LRM, eq. 4) or polynomial (PRM,
eq. 6) function of its ground coordinates, fitted by least squares (eq. 5) on
SCOPs; no collinearity equation is used for the row.

Here the features are the ground coordinates (X, Y) -- plus Z when the SCOPs' heights
vary (``use_height``) -- scaled to [-1, 1] by the SCOPs' extent; the full polynomial
of total degree ``degree`` is fitted by a QR least-squares solve and evaluated as one
matrix product.  The column comes from the collinearity at the predicted row (one
collinearity evaluation) or, with ``column="regression"``, from the same kind of
model fitted to the SCOPs' columns (no collinearity at all).

The row is affine in (X, Y, Z) only for a straight orbit at constant attitude (the
``linear`` preset, where ``lrm`` is exact); on a curved orbit with attitude rates the
LRM leaves a systematic error (about 0.01 px on the paper presets), which ``prm``
removes.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer.geometry.kernels import NUMBA_AVAILABLE
from explorer.methods._compiled import polynomial_predict
from explorer.methods._lm import GroundFeatures, take_params
from explorer.methods._polynomial import CHUNK, design_matrix, monomial_exponents, qr_least_squares
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.points import PointSet

__all__ = ["CHUNK", "LinearRegressionMethod", "PolynomialRegressionMethod", "design_matrix", "monomial_exponents",
           "qr_least_squares"]


class _RegressionBase(BestScanlineMethod):
    """Polynomial regression of the row (and optionally the column) on ground coordinates.

    Parameters
    ----------
    scene : Scene
    degree : int
        Total degree of the polynomial (``lrm``: 1).
    use_height : bool or None
        Include Z as a feature; default (None): only when the SCOPs' heights span more
        than 1 m (the papers fit (X, Y) on the mean-height plane).
    column : {"collinearity", "regression"}
        Column from the collinearity at the predicted row (1 CE per point) or from a
        second regression fitted to the SCOPs' columns (0 CE).
    domain_margin : float
        Ground points whose normalised features leave ``[-1 - m, 1 + m]`` (the SCOPs'
        extent plus this fraction of its half-width) are not located: ``converged`` and
        ``inside`` are False there.
    height_tolerance_m : float
        Without Z, points farther than this from the SCOPs' height are likewise refused.
    """

    family = "learned"
    needs_line_geometry = False  # ground / image pairs only: runs on any sensor, an RPC included
    needs_fit = True
    exactness = "approximate"
    _fixed_degree: int | None = None

    def __init__(self, scene, **params) -> None:
        defaults = {
            "use_height": None, "column": "collinearity", "domain_margin": 0.05,
            "height_tolerance_m": 1.0,
        }
        if self._fixed_degree is None:
            defaults["degree"] = 2
        p = take_params(self.name, params, defaults)
        super().__init__(scene, **p)
        self.degree = int(p["degree"] if "degree" in p else self._fixed_degree or 0)  # one of the two is set
        if self.degree < 1:
            raise ValueError(f"{self.name}: degree must be >= 1, got {self.degree}")
        if p["column"] not in ("collinearity", "regression"):
            raise ValueError(f"{self.name}: column must be 'collinearity' or 'regression', got {p['column']!r}")
        self.column_mode = p["column"]

    def _fit(self, control: PointSet) -> None:
        p = self.params
        self.features = GroundFeatures(control, p["use_height"], p["domain_margin"], p["height_tolerance_m"])
        self.exponents = monomial_exponents(self.features.n_features, self.degree)
        n_coef = self.exponents.shape[0]
        if len(control) < n_coef:
            names = "(X, Y, Z)" if self.features.use_height else "(X, Y)"
            raise ValueError(
                f"{self.name}: a degree-{self.degree} polynomial in {names} has {n_coef} coefficients; "
                f"{len(control)} control points are too few"
            )
        f, _ = self.features(control.ground)
        a = design_matrix(f, self.exponents)
        self.row_coef, cond = qr_least_squares(a, control.row, self.name)
        self.col_coef = None
        if self.column_mode == "regression":
            self.col_coef, _ = qr_least_squares(a, control.col, self.name)
        res = a @ self.row_coef - control.row
        self.fit_info = {
            "n_control": len(control),
            "degree": self.degree,
            "n_coefficients": n_coef,
            "terms": self.exponents.tolist(),
            "row_coefficients": self.row_coef.tolist(),
            "condition_number": cond,
            "train_rmse_px": float(np.sqrt(np.mean(res**2))),
            "train_max_px": float(np.max(np.abs(res))),
            "column": self.column_mode,
            "converged": True,
            **self.features.info(),
        }
        if self.col_coef is not None:
            cres = a @ self.col_coef - control.col
            self.fit_info["col_coefficients"] = self.col_coef.tolist()
            self.fit_info["col_train_rmse_px"] = float(np.sqrt(np.mean(cres**2)))

    def _predict(self, features: np.ndarray, coef: np.ndarray) -> np.ndarray:
        """Polynomial value (N,) in chunks: one (chunk, P) @ (P,) product per block."""
        out = np.empty(features.shape[0])
        for s in range(0, features.shape[0], CHUNK):
            out[s:s + CHUNK] = design_matrix(features[s:s + CHUNK], self.exponents) @ coef
        return out

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        if NUMBA_AVAILABLE:  # one compiled pass: features, domain flags, row (and column) polynomials
            coef = self.row_coef[:, None] if self.col_coef is None else np.stack([self.row_coef, self.col_coef], 1)
            values, ok = polynomial_predict(self.features, ground, self.exponents, coef)
            row = values[0]
            col = None if self.col_coef is None else values[1]
        else:
            f, ok = self.features(ground)
            row = self._predict(f, self.row_coef)
            col = None if self.col_coef is None else self._predict(f, self.col_coef)
        ce = np.zeros(row.shape, dtype=np.int64)
        return self._result(ground, row, ok, ce, col=col, trace=[row.copy()] if trace else None,
                            info={"in_domain": ok}, mask=ok)


@register
class LinearRegressionMethod(_RegressionBase):
    """``lrm``: the row as an affine function of (X, Y[, Z]) fitted on SCOPs (Sensors 24:5594, eq. 4-5).

    Parameters: see :class:`_RegressionBase` (no ``degree``).
    """

    name = "lrm"
    label = "LRM-BSD"
    reference = "Ahooei Nezhad, Valadan Zoej, Youssefi, Ghaderpour (2024) Sensors 24:5594"
    _fixed_degree = 1


@register
class PolynomialRegressionMethod(_RegressionBase):
    """``prm``: the row as a full polynomial of total degree ``degree`` (default 2) in
    normalised (X, Y[, Z]) fitted on SCOPs (Sensors 24:5594, eq. 6).

    Parameters: see :class:`_RegressionBase`; ``degree`` (int, default 2).
    """

    name = "prm"
    label = "PRM-BSD"
    reference = "Ahooei Nezhad, Valadan Zoej, Youssefi, Ghaderpour (2024) Sensors 24:5594"
