"""Fold an image-space correction into an RPC, so that the adjusted model is an ordinary RPC file.

``row' = row + correction(row, col)`` is written back as new numerators over the *same* denominators
and normalisation: with ``t = (row' - row_offset) / row_scale`` the new numerator is the cubic
polynomial that best fits ``t * den`` (least squares weighted by ``1 / den^2``, i.e. in normalised
pixels) on an 11 x 11 x 11 grid of the normalised cube ``[-1, 1]^3``.  A shift and the ``row_per_row`` /
``col_per_col`` terms fold exactly (the target is ``a num + b den``, a cubic); the cross terms
(``row_per_col`` multiplies ``col_num / col_den``) and the quadratic terms of ``poly2`` fold exactly only
when the two denominators are equal, otherwise to the residual the fit states, measured on a finer,
staggered 16 x 16 x 16 grid of the cube (pixels; typically 1e-6 px for an affine of 1e-4).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from explorer.refine.corrections import apply_correction
from explorer.rpc.model import RationalFunctionModel, evaluate_rpc00b_polynomial, rpc00b_monomials

__all__ = ["FoldResult", "fold_correction"]


@dataclass(frozen=True)
class FoldResult:
    """The adjusted RPC and how far it is from model + correction (pixels, on the normalised cube)."""

    rpc: RationalFunctionModel
    max_residual_px: float
    rms_residual_px: float


def _cube(n: int, stagger: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.linspace(-1.0, 1.0, n)
    if stagger:
        t = (t[:-1] + t[1:]) / 2.0
    x, y, z = np.meshgrid(t, t, t, indexing="ij")
    return x.ravel(), y.ravel(), z.ravel()


def _corrected(rpc: RationalFunctionModel, model: str, params: np.ndarray,
               x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    row_n, col_n = rpc.normalized_projection(x, y, z)
    row, col = row_n * rpc.row_scale + rpc.row_offset, col_n * rpc.col_scale + rpc.col_offset
    return apply_correction(model, np.asarray(params, dtype=np.float64), row, col)


def fold_correction(rpc: RationalFunctionModel, model: str, params: np.ndarray) -> FoldResult:
    """The RPC whose projection is ``rpc``'s corrected by ``model`` with ``params``.

    Parameters
    ----------
    rpc : RationalFunctionModel
    model : {"shift", "affine", "poly2"}
    params : ndarray, shape (P,)

    Returns
    -------
    FoldResult
        The new model (image-to-ground functions of the source dropped: they no longer match) and the
        folding residual in pixels (module docstring).
    """
    x, y, z = _cube(11, False)
    row, col = _corrected(rpc, model, params, x, y, z)
    monomials = rpc00b_monomials(x, y, z)
    new: dict[str, np.ndarray] = {}
    for key, target, offset, scale in (("row", row, rpc.row_offset, rpc.row_scale),
                                       ("col", col, rpc.col_offset, rpc.col_scale)):
        den_coeffs = getattr(rpc, f"{key}_den")
        den = evaluate_rpc00b_polynomial(den_coeffs, x, y, z)
        t = (target - offset) / scale
        a = monomials / den[:, None]
        new[f"{key}_num"] = np.asarray(np.linalg.lstsq(a, t, rcond=None)[0], dtype=np.float64)
    adjusted = replace(rpc, row_num=new["row_num"], col_num=new["col_num"], inverse=None,
                       metadata={**rpc.metadata, "refined": model})
    xs, ys, zs = _cube(17, True)
    want_row, want_col = _corrected(rpc, model, params, xs, ys, zs)
    got_row, got_col = adjusted.normalized_projection(xs, ys, zs)
    d = np.concatenate([got_row * rpc.row_scale + rpc.row_offset - want_row,
                        got_col * rpc.col_scale + rpc.col_offset - want_col])
    return FoldResult(adjusted, float(np.max(np.abs(d))), float(np.sqrt(np.mean(d * d))))
