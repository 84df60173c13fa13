"""A differentiable (torch, float64, CPU) ground to image of an RPC with an image-space correction.

:class:`TorchRPC` evaluates :meth:`explorer.rpc.model.RationalFunctionModel.projection` with the very
polynomial function of the compiled path (:func:`explorer.rpc.polynomial.horner_rpc00b`, the same
operations in the same order) on torch tensors, so that autograd gives the derivatives of (row, col)
with respect to the ground point (longitude, latitude, height) and to the correction parameters
(:mod:`explorer.refine.corrections`).  The two paths agree to 1e-9 px (``tests/refine``).

torch is imported by this module only; ``import explorer`` and ``import explorer.refine`` never load it.
"""

from __future__ import annotations

from typing import Any

import torch

from explorer.refine.corrections import apply_correction, correction_names
from explorer.rpc.model import RationalFunctionModel
from explorer.rpc.polynomial import horner_rpc00b

__all__ = ["TorchRPC"]


class TorchRPC:
    """Ground (lon, lat, h) -> corrected (row, col) of one RPC, differentiable.

    Parameters
    ----------
    rpc : RationalFunctionModel
    correction : {"shift", "affine", "poly2"}
        Image-space correction model (parameters :func:`~explorer.refine.corrections.correction_names`).
    """

    def __init__(self, rpc: RationalFunctionModel, correction: str = "affine") -> None:
        self.rpc = rpc
        self.correction = correction
        self.parameter_names = correction_names(correction)
        self._coefficients = [[float(v) for v in c] for c in (rpc.row_num, rpc.row_den, rpc.col_num, rpc.col_den)]

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    def model_pixels(self, lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Uncorrected (row, col), each shape (N,), of ground points (N,): degrees, degrees, metres."""
        m = self.rpc
        x = (lon - m.lon_offset) / m.lon_scale
        y = (lat - m.lat_offset) / m.lat_scale
        z = (h - m.height_offset) / m.height_scale
        rn, rd, cn, cd = self._coefficients
        row_n = horner_rpc00b(rn, x, y, z) / horner_rpc00b(rd, x, y, z)
        col_n = horner_rpc00b(cn, x, y, z) / horner_rpc00b(cd, x, y, z)
        return row_n * m.row_scale + m.row_offset, col_n * m.col_scale + m.col_offset

    def project(self, lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor,
                params: torch.Tensor | Any) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col), each (N,), of ground points (N,); ``params`` shape (P,) or (N, P)."""
        row, col = self.model_pixels(lon, lat, h)
        return apply_correction(self.correction, params, row, col)
