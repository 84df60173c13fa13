"""Image-space corrections of an RPC (Grodecki & Dial's bias compensation): shift, affine, poly2.

The measured image position of a ground point is the model's plus the correction
(``docs/conventions.md`` pixels, 0-based, integer = pixel centre)::

    row_measured = row_model + row_shift + row_per_row * row_model + row_per_col * col_model
                   [+ row_per_row2 * row_model**2 + row_per_row_col * row_model * col_model
                    + row_per_col2 * col_model**2]                                    (poly2 only)

and the same for the column with ``col_*`` parameters.  The affine names are the issue's and the
report's (``report.json`` ``parameters``); the coefficients multiply *absolute* model pixels, as in
Grodecki & Dial (2003), so ``row_per_row = 1e-4`` is a scale of 1e-4 and ``row_per_col`` a shear.

The functions work on torch tensors (the differentiable model) and on numpy arrays (the same
operations), so the adjusted model is applied identically by both paths.
"""

from __future__ import annotations

from typing import Any

#: Parameter names per correction model, in the order of the parameter vector.
CORRECTION_PARAMETERS: dict[str, tuple[str, ...]] = {
    "shift": ("row_shift", "col_shift"),
    "affine": ("row_shift", "row_per_row", "row_per_col", "col_shift", "col_per_row", "col_per_col"),
    "poly2": (
        "row_shift", "row_per_row", "row_per_col", "row_per_row2", "row_per_row_col", "row_per_col2",
        "col_shift", "col_per_row", "col_per_col", "col_per_row2", "col_per_row_col", "col_per_col2",
    ),
}  # fmt: skip

#: Correction models that are affine in (row, col), so that they fold exactly into an RPC's offsets and
#: numerators up to the cross terms (see :func:`explorer.refine.fold.fold_correction`).
AFFINE_MODELS = ("shift", "affine")


def correction_names(model: str) -> tuple[str, ...]:
    """Parameter names of an image-space correction ``model`` (``shift``, ``affine`` or ``poly2``)."""
    from explorer.errors import UnknownNameError

    try:
        return CORRECTION_PARAMETERS[model]
    except KeyError:
        raise UnknownNameError("RPC correction model", model, CORRECTION_PARAMETERS) from None


def apply_correction(model: str, params: Any, row: Any, col: Any) -> tuple[Any, Any]:
    """Corrected (row, col) of model pixels.

    Parameters
    ----------
    model : {"shift", "affine", "poly2"}
    params : tensor or ndarray, shape (..., P)
        Parameters in the order of :data:`CORRECTION_PARAMETERS` ``[model]``; leading dimensions
        broadcast against ``row`` (one row of parameters per point, or one for all).
    row, col : tensor or ndarray, shape (...)
        Model pixels.

    Returns
    -------
    row, col : same type, shape (...)
    """
    p = [params[..., k] for k in range(len(correction_names(model)))]
    if model == "shift":
        return row + p[0], col + p[1]
    if model == "affine":
        return (row + (p[0] + p[1] * row + p[2] * col),
                col + (p[3] + p[4] * row + p[5] * col))
    rr, rc, cc = row * row, row * col, col * col
    return (row + (p[0] + p[1] * row + p[2] * col + p[3] * rr + p[4] * rc + p[5] * cc),
            col + (p[6] + p[7] * row + p[8] * col + p[9] * rr + p[10] * rc + p[11] * cc))


__all__ = ["AFFINE_MODELS", "CORRECTION_PARAMETERS", "apply_correction", "correction_names"]
