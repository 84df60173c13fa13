"""Agreement of a scene (rigorous or MPC) with a vendor RPC over the whole image.

A cell-centred grid of image points is intersected by the scene with height planes spanning
the RPC's validity range (``height_offset +- |height_scale|``); each ground point goes back to
the image through the RPC (at its exact ellipsoidal height); the differences are reported in
pixels (RMS, max, per-height bias).  Optionally a fresh cubic polynomial RPC (20 terms per
coordinate, denominator 1: the rational fit is unstable on these grids) is fitted to the scene
on an independent grid (``explorer.rpc.fit.fit_rfm_from_gcps``) to measure how much of the
disagreement a cubic rational function can represent at all (the RPC's own approximation
error).  Heights are planes of the local ENU frame (``docs/conventions.md#frames``); the
RPC is evaluated at each point's geodetic height, so the comparison is exact.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from explorer.real.from_rpc import _grid
from explorer.rpc import RationalFunctionModel
from explorer.scene import Scene

__all__ = ["RPCComparison", "compare_with_rpc"]


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a)))) if np.size(a) else float("nan")


@dataclass
class RPCComparison:
    """Scene -> RPC disagreement in pixels.

    Attributes
    ----------
    drow, dcol : ndarray, shape (N,)
        RPC projection minus the image point the scene started from.
    heights : ndarray, shape (N,)
        Plane height of each point, metres.
    rms_px, max_px : float
        Of the Euclidean difference.
    bias_row_px, bias_col_px : float
        Mean differences (a constant image shift).
    rms_unbiased_px : float
        RMS after removing the mean shift.
    per_layer : list of dict
        ``height_m``, ``bias_row_px``, ``bias_col_px``, ``rms_px``, ``std_row_px``, ``std_col_px``.
    refit : dict
        ``refit_rms_px``/``refit_max_px`` (cubic polynomial RPC fitted to the scene, on the comparison
        points) and ``refit_vs_vendor_rms_px``/``_max_px``; empty when not computed.
    """

    drow: np.ndarray
    dcol: np.ndarray
    heights: np.ndarray
    rms_px: float
    max_px: float
    bias_row_px: float
    bias_col_px: float
    rms_unbiased_px: float
    per_layer: list[dict] = field(default_factory=list)
    refit: dict = field(default_factory=dict)

    @property
    def n_points(self) -> int:
        return int(self.drow.size)

    def to_dict(self) -> dict:
        return {
            "n_points": self.n_points, "rms_px": self.rms_px, "max_px": self.max_px,
            "rms_row_px": _rms(self.drow), "rms_col_px": _rms(self.dcol),
            "bias_row_px": self.bias_row_px, "bias_col_px": self.bias_col_px,
            "rms_unbiased_px": self.rms_unbiased_px, "per_layer": self.per_layer, **self.refit,
        }  # fmt: skip

    def summary(self) -> str:
        lines = [
            f"rigorous model vs RPC on {self.n_points} points ({len(self.per_layer)} heights):"
            f" RMS {self.rms_px:.4f} px, max {self.max_px:.4f} px",
            f"  mean shift row {self.bias_row_px:+.4f} px, col {self.bias_col_px:+.4f} px;"
            f" RMS without it {self.rms_unbiased_px:.4f} px",
        ]
        for layer in self.per_layer:
            lines.append(
                f"  h {layer['height_m']:8.1f} m: shift ({layer['bias_row_px']:+.4f}, {layer['bias_col_px']:+.4f})"
                f" px, RMS {layer['rms_px']:.4f} px"
            )
        if self.refit:
            lines.append(
                f"  cubic RPC refitted to the model: own error RMS {self.refit['refit_rms_px']:.4f} px "
                f"(max {self.refit['refit_max_px']:.4f}); refit vs vendor RPC RMS "
                f"{self.refit['refit_vs_vendor_rms_px']:.4f} px (max {self.refit['refit_vs_vendor_max_px']:.4f})"
            )
        return "\n".join(lines)


def compare_with_rpc(
    scene: Scene,
    rpc: RationalFunctionModel | None = None,
    *,
    n: int = 400,
    layers: int = 5,
    height_range: tuple[float, float] | None = None,
    refit: bool = True,
) -> RPCComparison:
    """Compare ``scene``'s image -> ground with the RPC's ground -> image.

    Parameters
    ----------
    scene : Scene
        Any scene (a :class:`~explorer.real.linescan.RigorousLineScanScene` carries its RPC).
    rpc : RationalFunctionModel, optional
        Default ``scene.rpc``.
    n : int
        About this many image points per height (cell-centred grid).
    layers : int
        Heights spanning ``height_range`` (default the RPC's validity range).
    refit : bool
        Also fit a cubic RPC to the scene (on a different image grid) and report its error.
    """
    rpc = getattr(scene, "rpc", None) if rpc is None else rpc
    if rpc is None:
        raise ValueError("no RPC to compare with")
    lo, hi = rpc.height_range(1.0) if height_range is None else height_range
    heights = np.linspace(lo, hi, max(layers, 1))
    r, c = _grid(n, scene.n_rows, scene.n_columns, True)
    rows = np.tile(r, heights.size)
    cols = np.tile(c, heights.size)
    hh = np.repeat(heights, r.size)
    ground = scene.image_to_ground(rows, cols, height=hh)
    lon, lat, h_ell = scene.frame.enu_to_geodetic(ground)
    r_rpc, c_rpc = rpc.projection(lon, lat, h_ell)
    drow, dcol = r_rpc - rows, c_rpc - cols
    d = np.hypot(drow, dcol)
    per_layer = []
    for k, h in enumerate(heights):
        sl = slice(k * r.size, (k + 1) * r.size)
        per_layer.append({
            "height_m": float(h), "bias_row_px": float(drow[sl].mean()), "bias_col_px": float(dcol[sl].mean()),
            "rms_px": _rms(d[sl]), "std_row_px": float(drow[sl].std()), "std_col_px": float(dcol[sl].std()),
        })  # fmt: skip
    out = RPCComparison(
        drow=drow, dcol=dcol, heights=hh, rms_px=_rms(d), max_px=float(d.max()),
        bias_row_px=float(drow.mean()), bias_col_px=float(dcol.mean()),
        rms_unbiased_px=_rms(np.hypot(drow - drow.mean(), dcol - dcol.mean())), per_layer=per_layer,
    )  # fmt: skip
    if refit:
        from explorer.rpc.fit import fit_rfm_from_gcps

        fr, fc = _grid(2 * n, scene.n_rows, scene.n_columns, False)
        fh = np.linspace(lo, hi, max(layers, 3) + 2)
        fr3, fc3, fh3 = np.tile(fr, fh.size), np.tile(fc, fh.size), np.repeat(fh, fr.size)
        g = scene.image_to_ground(fr3, fc3, height=fh3)
        glon, glat, gh = scene.frame.enu_to_geodetic(g)
        fit = fit_rfm_from_gcps(glon, glat, gh, fr3, fc3, order=3, rational=False)
        rr, cc = fit.model.projection(lon, lat, h_ell)
        own = np.hypot(rr - rows, cc - cols)
        vend = np.hypot(rr - r_rpc, cc - c_rpc)
        out.refit = {
            "refit_rms_px": _rms(own), "refit_max_px": float(own.max()),
            "refit_vs_vendor_rms_px": _rms(vend), "refit_vs_vendor_max_px": float(vend.max()),
        }  # fmt: skip
    return out
