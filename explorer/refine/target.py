"""What a refinement of a sensor adjusts: the sensor itself where it is refinable, else an MPC stand-in of it.

:func:`explorer.refine.images.image_adapter` refines an RPC (image-space corrections) and an MPC scene (its
exterior polynomials).  A sensor it does not refine yet (a rigorous DIMAP / DG line-scan model, a USGS CSM
camera) is refined through an MPC scene that stands in for it: a stand-in the source already has (the MPC fitted
to a CSM camera), else an MPC fitted to the sensor (:func:`explorer.real.mpc_fit.mpc_scene_from_sensor`).  The
stand-in is labelled so, and :meth:`RefineTarget.stand_in_error_px` measures how far it is from the sensor at
the very points of the adjustment -- the floor under any residual the refinement can reach.  Once the sensor's
own differentiable model is refinable (``image_adapter`` accepts it), it is adjusted directly.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.refine.points_io import PointTable

__all__ = ["RefineTarget", "refine_target"]


@dataclass
class RefineTarget:
    """The model a refinement adjusts.

    Attributes
    ----------
    model : RationalFunctionModel or Scene
        What :func:`explorer.refine.adjust.refine_images` adjusts.
    label : str
        What it is, for people ("the RPC itself", "MPC degree 3 fitted to the rigorous model (a stand-in)").
    truth : Sensor or None
        The sensor the model stands in for (None when the model is the sensor itself).
    """

    model: Any
    label: str
    truth: Any = None

    @property
    def is_stand_in(self) -> bool:
        return self.truth is not None

    def stand_in_error_px(self, *tables: PointTable | None) -> float | None:
        """Largest pixel distance (one coordinate's max, pixels) between the stand-in and the sensor at the
        ground points of ``tables`` (each projected by both); None without a stand-in or points."""
        if self.truth is None:
            return None
        worst: float | None = None
        for table in tables:
            if table is None or not table.has_ground or not len(table):
                continue
            assert table.lon is not None and table.lat is not None and table.h is not None
            true = self.truth.project_geodetic(table.lon, table.lat, table.h)
            row, col = self.model.geodetic_to_image(table.lon, table.lat, table.h)
            ok = np.asarray(true.valid, dtype=bool) & np.isfinite(row) & np.isfinite(col)
            if ok.any():
                err = float(np.max(np.abs(np.concatenate([row[ok] - true.row[ok], col[ok] - true.col[ok]]))))
                worst = err if worst is None else max(worst, err)
        return worst


def _refinable(model: Any) -> bool:
    from explorer.refine.images import image_adapter

    try:
        image_adapter(model)
    except InputError:
        return False
    return True


def refine_target(sensor: Any, *, stand_ins: Iterable[Any] = (), degree: int = 3,
                  what: str | None = None) -> RefineTarget:
    """The model to adjust for ``sensor``.

    Parameters
    ----------
    sensor : RationalFunctionModel or Sensor
        The source's sensor (the truth its control points were measured in).
    stand_ins : iterable of Sensor
        Models that already stand in for it (the first refinable one is used before fitting one).
    degree : int
        Degree of the MPC polynomials fitted to a sensor that is not refinable and has no refinable stand-in.
    what : str, optional
        How to call the sensor in the label (default: its class name).

    Raises
    ------
    InputError
        A sensor that is neither refinable nor has scanlines to fit an MPC scene to.
    """
    if _refinable(sensor):
        return RefineTarget(sensor, "the sensor itself" if what is None else what)
    name = what or type(sensor).__name__
    for candidate in stand_ins:
        if _refinable(candidate):
            return RefineTarget(candidate, f"the MPC fitted to {name} (a stand-in)", sensor)
    from explorer.sensor import has_line_geometry

    if not has_line_geometry(sensor):
        raise InputError(f"cannot refine a {type(sensor).__name__}: it is not refinable and has no scanlines to "
                         "fit an MPC stand-in to")
    to_mpc = getattr(sensor, "to_mpc_scene", None)
    camera = getattr(sensor, "camera", None)
    if to_mpc is not None:  # a rigorous line-scan model: its own fit (explorer.real.linescan)
        mpc, _ = to_mpc(degree=degree, n_check=0)
    elif camera is not None:  # a CSM camera (CsmScene): the MPC fitted to the camera (explorer.real.csm_scene)
        from explorer.real.csm_scene import scene_from_camera

        mpc = scene_from_camera(camera, degree=degree, n_check=0)
    else:
        from explorer.real.mpc_fit import mpc_scene_from_sensor

        h = float(sensor.terrain.mean_height)
        mpc, _ = mpc_scene_from_sensor(sensor, height_range=(h - 500.0, h + 500.0), degree=degree, n_check=0)
    return RefineTarget(mpc, f"an MPC degree {degree} fitted to {name} (a stand-in)", sensor)
