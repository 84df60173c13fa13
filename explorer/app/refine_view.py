"""The explorer's *Refinement* folder (``pushbroom explore SOURCE --gcps gcps.csv``, ``docs/refine.md``).

A correction model dropdown and a list of dropped point ids; every change re-adjusts the sensor to the
control points (:func:`explorer.refine.adjust.refine_images`, in a background thread, the newest change
winning) and redraws the refinement panels (:mod:`explorer.panels.refine`): the residual vectors before and
after, the field the adjustment removed, the parameter table with sigmas and, for a sensor with scanlines,
the original and adjusted trajectory -- as a panel and in the 3D scene (:mod:`explorer.scene3d.refine`, the
displacement exaggerated with the factor stated).  What is adjusted is :func:`refine_target_of` the source:
the RPC itself for ``--rpc``, the MPC scene of ``--scene`` / a preset, the rigorous DIMAP / DG model or the
CSM camera itself, and for a sensor no adapter refines the MPC that stands in for it, labelled so with its
distance from the sensor at the points.  A bad configuration (too few points left, a degenerate one) shows
its one-line message in the folder.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from explorer.errors import ExplorerError, InputError
from explorer.refine.points_io import PointTable
from explorer.refine.target import RefineTarget

__all__ = ["RefineView", "refine_target_of"]


def refine_target_of(source: Any) -> RefineTarget:
    """The model a source's refinement adjusts (:func:`explorer.refine.target.refine_target`): the RPC file
    itself for ``--rpc`` (not the MPC resected from it), the scene of ``--scene`` and of a preset (built with
    the preset's defaults), and the sensor itself or its MPC stand-in for ``--dimap``, ``--dg`` and ``--isd``."""
    from explorer.refine.target import refine_target

    if source.kind == "rpc":
        from explorer.rpc import read_rpc

        return RefineTarget(read_rpc(source.path), "the RPC itself (image-space correction)")
    scene = source.scene
    if scene is None and source.kind == "preset":
        from explorer.presets import build_scene

        scene = build_scene(source.label)
    if scene is None:
        raise InputError(f"--gcps: the --{source.kind} source has no sensor to refine")
    stand_ins = [source.stand_in.sensor] if source.stand_in is not None else []
    what = {"dimap": "the rigorous DIMAP model", "dg": "the rigorous DG model", "isd": "the CSM camera"}.get(
        source.kind, f"the {type(scene).__name__}")
    target = refine_target(scene, stand_ins=stand_ins, what=what)
    if not target.is_stand_in:
        target.label = f"{what} itself"
    return target


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
    sensor : RefineTarget, RationalFunctionModel or Scene
        What is adjusted (a bare model is the sensor itself).
    control : PointTable
    check : PointTable, optional
    sigma_px : float
        Stated sigma of a measured coordinate, pixels.
    scene_api : viser SceneApi, optional
        Where the trajectories are drawn in 3D (``server.scene``); none: no 3D.
    display_frame : callable, optional
        Returns the 3D view's current :class:`~explorer.scene3d.builders.DisplayFrame` (None before the
        first scene is drawn); the app calls :meth:`draw_3d` again when it changes.
    on_drawn : callable, optional
        Called after every (re)draw of the 3D trajectories, outside the view's locks: the app lays its labels
        out again (the trajectories' label among them, :meth:`label_nodes`).
    """

    def __init__(self, gui: Any, sensor: Any, control: PointTable, check: PointTable | None = None,
                 sigma_px: float = 0.5, *, scene_api: Any = None,
                 display_frame: Callable[[], Any] | None = None,
                 on_drawn: Callable[[], None] | None = None) -> None:
        from explorer.refine.images import image_adapter

        self.target = sensor if isinstance(sensor, RefineTarget) else RefineTarget(sensor, "the sensor itself")
        self.sensor, self.control, self.check, self.sigma_px = self.target.model, control, check, sigma_px
        adapter = image_adapter(self.sensor)
        self.models = list(adapter.models)
        from explorer.sensor import has_line_geometry

        self.has_trajectory = has_line_geometry(self.sensor)
        self.is_scene = adapter.kind == "scene"
        self.stand_in_px = self.target.stand_in_error_px(control, check)
        self.scene_api, self.display_frame, self.on_drawn = scene_api, display_frame, on_drawn
        self.refinement: Any = None
        self.trajectory_3d: dict[str, Any] | None = None
        self.shown = True  # the 3D trajectories are visible (the app hides them while another scene is shown)
        self._nodes: dict[str, Any] = {}
        self.error: str | None = None
        with gui.add_folder("Refinement"):
            self.what = gui.add_markdown(self._what_text())
            self.model = gui.add_dropdown("Model", self.models,
                                          initial_value="affine" if "affine" in self.models else self.models[0])
            self.drop = gui.add_text("Drop point ids", initial_value="",
                                     hint="comma-separated control point ids left out of the adjustment")
            self.summary = gui.add_markdown("")
            self.trajectory_text = gui.add_markdown("", visible=self.has_trajectory)
            import plotly.graph_objects as go

            empty = go.Figure()
            self.quiver = gui.add_plotly(empty, aspect=1.6)
            self.field = gui.add_plotly(empty, aspect=1.8)
            self.table = gui.add_plotly(empty, aspect=1.4)
            self.trajectory = gui.add_plotly(empty, aspect=1.2, visible=self.has_trajectory)
        self._gen = 0
        self._gen_lock = threading.Lock()
        self._run_lock = threading.Lock()  # one adjustment at a time
        self._draw_lock = threading.Lock()  # the app's worker redraws the 3D too (draw_3d)
        self.thread: threading.Thread | None = None
        self.model.on_update(lambda _: self.request_update())
        self.drop.on_update(lambda _: self.request_update())
        self.update()

    def _what_text(self) -> str:
        text = f"Adjusting **{self.target.label}**."
        if self.stand_in_px is not None:
            text += (f" The stand-in is {self.stand_in_px:.3g} px (largest coordinate) from the sensor at the "
                     "control and check points: residuals below that are out of its reach.")
        return text

    def dropped(self) -> set[str]:
        return {t.strip() for t in str(self.drop.value).split(",") if t.strip()}

    def _next_gen(self) -> int:
        with self._gen_lock:
            self._gen += 1
            return self._gen

    def request_update(self) -> threading.Thread:
        """A change in the GUI: re-adjust in a background thread, so the GUI stays live while a rigorous model
        adjusts (seconds); the folder says so meanwhile, and a newer change supersedes one still waiting."""
        gen = self._next_gen()
        self.summary.content = f"*Re-adjusting ({self.model.value}, {len(self.dropped())} point(s) dropped) ...*"
        self.thread = threading.Thread(target=self._run, args=(gen,), daemon=True, name="refine-view")
        self.thread.start()
        return self.thread

    def _run(self, gen: int) -> None:
        with self._run_lock:
            if gen == self._gen:  # (else superseded while it waited)
                self._adjust(gen)

    def update(self) -> None:
        """Re-adjust now with the current model and points; redraw the panels and the 3D trajectories (or show
        the error)."""
        with self._run_lock:
            self._adjust(self._next_gen())

    def _adjust(self, gen: int) -> None:
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
            if gen == self._gen:
                self.error = " ".join(str(exc).split())
                self.summary.content = f"**Not adjusted:** {self.error}"
            return
        if gen != self._gen:
            return  # a newer change is waiting: its adjustment is shown instead
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
        if self.has_trajectory:
            self.trajectory.figure = trajectory_figure(ref, height=380)
            self.draw_3d()

    def draw_3d(self, visible: bool | None = None) -> None:
        """Draw (or redraw) the original and adjusted trajectories of the last adjustment in the 3D scene, in
        the app's current display frame; ``visible`` False hides them (another scene is shown), None keeps them
        as the app last asked (a re-adjustment)."""
        if not self.has_trajectory or self.refinement is None or self.scene_api is None:
            return
        frame = self.display_frame() if self.display_frame is not None else None
        if frame is None:
            return
        from explorer.refine.trajectory import refinement_trajectory
        from explorer.scene3d.refine import add_refined_trajectories

        with self._draw_lock:
            comparison = refinement_trajectory(self.refinement)
            for handle in self._nodes.values():
                handle.remove()
            self._nodes, info = add_refined_trajectories(self.scene_api, comparison, frame)
            if visible is not None:
                self.shown = bool(visible)
            for handle in self._nodes.values():
                handle.visible = self.shown
            self.trajectory_3d = info
            self.trajectory_text.content = f"3D: {info['text']}."
        if self.on_drawn is not None:
            self.on_drawn()

    def label_nodes(self) -> dict[str, tuple[Any, tuple[np.ndarray, ...]]]:
        """The 3D labels drawn and shown now, ``{node name: (handle, alternative points (3,) display km)}``
        (the label may stand at any of them instead of its own: :mod:`explorer.scene3d.labels`); empty while the
        trajectories are hidden or not drawn."""
        with self._draw_lock:
            if not self.shown or self.trajectory_3d is None:
                return {}
            alternatives = tuple(np.asarray(p, dtype=np.float64) for p in self.trajectory_3d["label_alternatives"])
            return {k: (h, alternatives) for k, h in self._nodes.items() if k == "/refine/label"}
