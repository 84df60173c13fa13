"""Two images: triangulation, exact epipolar curves and epipolar resampling grids of pushbroom pairs.

=======================  =====================================================================
:func:`triangulate`      matched pixels of two sensors -> ground points, ray distance, flags
:func:`epipolar_curve`   the exact right-image curve of a left pixel over heights
:func:`epipolar_grids`   left/right resampling grids as shareloc and OTB make them
=======================  =====================================================================

Any :class:`explorer.sensor.Sensor` (RPC, rigorous line-scan, CSM, MPC scene) or an RPC model from
:func:`explorer.read_rpc` is accepted for either image; heights are ellipsoidal.  Guide: ``docs/stereo.md``.
Names are imported on first use.
"""

from __future__ import annotations

from explorer._lazy import lazy_names

_LAZY: dict[str, str] = {
    "triangulate": "explorer.stereo.triangulation",
    "Triangulation": "explorer.stereo.triangulation",
    "epipolar_curve": "explorer.stereo.epipolar",
    "EpipolarCurve": "explorer.stereo.epipolar",
    "epipolar_grids": "explorer.stereo.grids",
    "EpipolarGrids": "explorer.stereo.grids",
    "write_grids": "explorer.stereo.grids",
    "approximation_maps": "explorer.stereo.approximation",
    "ApproximationMaps": "explorer.stereo.approximation",
}


__getattr__, __dir__ = lazy_names(globals(), _LAZY)


__all__ = sorted(_LAZY)
