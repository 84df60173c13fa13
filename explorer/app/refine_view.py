"""The explorer's *Refinement* folder (``pushbroom explore --rpc FILE --gcps gcps.csv``, ``docs/refine.md``).

A correction model dropdown and a list of dropped point ids; every change re-adjusts the sensor to the
control points (:func:`explorer.refine.adjust.refine_images`) and redraws the refinement panels
(:mod:`explorer.panels.refine`): the residual vectors before and after, the field the adjustment removed,
the parameter table with sigmas and, for an MPC scene, the original and adjusted trajectory in 3D.
A bad configuration (too few points left, a degenerate one) shows its one-line message in the folder.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explorer.errors import ExplorerError, InputError
from explorer.refine.points_io import PointTable

__all__ = ["RefineView", "refine_sensor_of"]


def refine_sensor_of(source: Any) -> Any:
    """The model a source's refinement adjusts: the RPC file itself for ``--rpc``, the MPC scene for
    ``--scene``/presets; InputError for the rigorous and CSM sources (not refined yet)."""
    if source.kind == "rpc":
        from explorer.rpc import read_rpc

        return read_rpc(source.path)
    if source.kind == "scene" and source.scene is not None:
        return source.scene
    raise InputError(f"--gcps refines --rpc or --scene sources, not --{source.kind}")


def _subset(table: PointTable, keep: np.ndarray) -> PointTable:
    idx = np.flatnonzero(keep)
    return PointTable([table.ids[i] for i in idx], table.row[idx], table.col[idx],
                      None if table.lon is None else table.lon[idx], None if table.lat is None else table.lat[idx],
                      None if table.h is None else table.h[idx],
                      None if table.image is None else [table.image[i] for i in idx], table.path)


class RefineView:
    """The *Refinement* folder of a viser GUI, re-adjusting live.

    Parameters
    ----------
    gui : viser GUI API (``server.gui``)
    sensor : RationalFunctionModel or Scene
    control : PointTable
    check : PointTable, optional
    sigma_px : float
        Stated sigma of a measured coordinate, pixels.
    """

    def __init__(self, gui: Any, sensor: Any, control: PointTable, check: PointTable | None = None,
                 sigma_px: float = 0.5) -> None:
        from explorer.refine.images import image_adapter

        self.sensor, self.control, self.check, self.sigma_px = sensor, control, check, sigma_px
        adapter = image_adapter(sensor)
        self.models = list(adapter.models)
        self.is_scene = adapter.kind == "scene"
        self.refinement: Any = None
        self.error: str | None = None
        with gui.add_folder("Refinement"):
            self.model = gui.add_dropdown("Model", self.models,
                                          initial_value="affine" if "affine" in self.models else self.models[0])
            self.drop = gui.add_text("Drop point ids", initial_value="",
                                     hint="comma-separated control point ids left out of the adjustment")
            self.summary = gui.add_markdown("")
            import plotly.graph_objects as go

            empty = go.Figure()
            self.quiver = gui.add_plotly(empty, aspect=1.6)
            self.field = gui.add_plotly(empty, aspect=1.8)
            self.table = gui.add_plotly(empty, aspect=1.4)
            self.trajectory = gui.add_plotly(empty, aspect=1.2, visible=self.is_scene)
        self.model.on_update(lambda _: self.update())
        self.drop.on_update(lambda _: self.update())
        self.update()

    def dropped(self) -> set[str]:
        return {t.strip() for t in str(self.drop.value).split(",") if t.strip()}

    def update(self) -> None:
        """Re-adjust with the current model and points; redraw the panels (or show the error)."""
        from explorer.panels.refine import (
            correction_field_figure,
            parameter_table_figure,
            residual_quiver_figure,
            trajectory_figure,
        )
        from explorer.refine.adjust import refine_images

        dropped = self.dropped()
        unknown = sorted(dropped - set(self.control.ids))
        keep = np.asarray([i not in dropped for i in self.control.ids], dtype=bool)
        try:
            if unknown:
                raise InputError(f"no control point {', '.join(unknown)}")
            ref = refine_images([self.sensor], model=str(self.model.value), control=_subset(self.control, keep),
                                check=self.check, sigma_px=self.sigma_px)
        except ExplorerError as exc:
            self.error = " ".join(str(exc).split())
            self.summary.content = f"**Not adjusted:** {self.error}"
            return
        self.error = None
        self.refinement = ref
        rep = ref.report()

        def fmt(v: float | None) -> str:
            return "-" if v is None else f"{v:.3f}"

        self.summary.content = (f"**{rep['model']}**: sigma0 {rep['sigma0']:.3f}; control RMSE "
                                f"{fmt(rep['control_rmse_px_before'])} -> {fmt(rep['control_rmse_px'])} px, check RMSE "
                                f"{fmt(rep['check_rmse_px_before'])} -> {fmt(rep['check_rmse_px'])} px; "
                                f"{rep['n_outliers']} outlier(s); {int((~keep).sum())} point(s) dropped")
        self.quiver.figure = residual_quiver_figure(ref, height=380)
        self.field.figure = correction_field_figure(ref, height=320)
        self.table.figure = parameter_table_figure(ref)
        if self.is_scene:
            self.trajectory.figure = trajectory_figure(ref, height=380)
