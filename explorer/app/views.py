"""What the explorer draws: the update stages of :class:`explorer.app.gui.ExplorerApp`.

:class:`Views` is the drawing half of the app (a mixin): :meth:`Views.update` takes a
:class:`~explorer.app.model.Settings`, asks the model for the numbers and redraws only what
changed -- the scene (ground, DEM mesh, orbit), the SCP cloud, the panels, the selected point,
the accuracy sweep -- each stage keyed by what it depends on.  It also frames the camera of
every open browser on a new footprint, resets the view, and exports.
"""

from __future__ import annotations

import contextlib
import io
import threading
import time
import zipfile
from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, Any

import numpy as np

from explorer.app.model import SCOP_DENSITIES, SWEEP_PURPOSE, MethodRun, Selection, Settings, summary_markdown
from explorer.evaluate import STAND_IN_METHOD, evaluate_stand_in
from explorer.methods import registry
from explorer.panels import diverging_rgb
from explorer.points import PointSet
from explorer.scene import Scene
from explorer.sources import stand_in_truth, table_coverage_text

CANVAS_SETTLE_S = 10.0
"""A browser's canvas may still change shape (its panels docking) this long after it connected: its camera is
reframed for the new shape even if its reports still carry an earlier pose."""
MAPS_DRAWN_WAIT_S = 1.0
"""At most this long an update waits for a browser to report its new maps drawn before it sends the 3D part."""
VIEW_DRAWN_WAIT_S = 6.0
"""The longest an update waits for a browser to report its 3D batch drawn (the page reports it at the latest
:data:`explorer.app.controls.VIEW_MAX_MS` after it applied it)."""
SEND_WAIT_S = 0.1
"""How long an update waits for the browsers' connections to take the panels before it queues the 3D batch."""
SENT_POSES_KEPT = 8
"""How many earlier framings sent to a browser are remembered (a report at one of them is a stale framing)."""
STATUS_NAME_CHARS = 48
"""Scene names longer than this are shortened in the status line (the Scene control shows them whole)."""


def short_name(name: str, limit: int = STATUS_NAME_CHARS) -> str:
    """``name`` shortened in its middle to at most ``limit`` characters (a file name keeps its start, its
    end and the sensor in brackets)."""
    if len(name) <= limit:
        return name
    head = (limit - 1) * 3 // 5
    return name[:head] + "\u2026" + name[len(name) - (limit - 1 - head):]


def markdown_literal(text: str) -> str:
    """``text`` as literal characters in viser's Markdown inside a line (HTML-escaped; the characters Markdown
    would read as emphasis, code, links, strike-through or escapes -- ``\\`*_[]~|`` -- as numeric entities)."""
    import html

    return "".join(f"&#{ord(c)};" if c in "\\`*_[]~|" else c for c in html.escape(text, quote=True))


def status_name(name: str, limit: int = STATUS_NAME_CHARS) -> str:
    """A scene name for the status line (Markdown): shortened by :func:`short_name` when longer than
    ``limit``, the full name then in a tooltip (an HTML ``title``; viser's Markdown passes HTML through)."""
    shown = markdown_literal(short_name(name, limit))
    if len(name) <= limit:
        return shown
    import html

    return f'<span title="{html.escape(name, quote=True)}">{shown}</span>'


class Superseded(Exception):
    """A newer update request arrived; the current one stops at its next checkpoint."""


class Views:
    """Drawing stages of the explorer app (mixed into :class:`~explorer.app.gui.ExplorerApp`)."""

    # set by ExplorerApp
    server: Any
    model: Any
    handles: dict[str, Any]
    nodes: dict[str, Any]
    _sent: dict[str, Hashable]
    _F: Any
    _B: Any
    if TYPE_CHECKING:  # pragma: no cover  (provided by ExplorerApp)
        runs: dict[str, MethodRun]
        view_drawn: int
        _view_sent: int
        _view_deadline: float
        _views_drawn: dict[Any, int]
        pending: dict[str, str]
        sweeps: dict[str, list]
        selection: Selection | None
        frame: Any
        scene: Scene | None
        cloud_index: np.ndarray | None
        cloud_residual: np.ndarray | None
        last_update_s: float | None
        request_started: float | None
        last_times: dict[str, float]
        camera_pose: tuple | None
        client_poses: dict[Any, tuple]
        label_layout: dict[str, Any]
        label_boxes: dict[Any, dict[str, Any]]
        client_canvases: dict[Any, tuple[float, float, float]]
        _label_lock: Any
        label_alternatives: dict[str, tuple]
        _framed_clients: dict[Any, tuple]
        _client_since: dict[Any, float]
        _poses_sent: dict[Any, list]
        _camera_lock: Any
        _framing: tuple[np.ndarray, np.ndarray, np.ndarray | None]
        exports: int
        fits: Any
        methods_ready: threading.Event
        method_names: list[str]
        controls: Any
        max_cloud_points: int
        max_map_cells: int
        fit_wait_s: float
        background: bool
        _lock: threading.Condition
        _completed_gen: int
        _gen: int
        _status: Callable[..., None]
        _check: Callable[[int | None], None]
        _get_fits: Callable[..., dict]
        _pending_text: Callable[[str, Settings], str]
        _maps_shown: Callable[[Settings], None]
        settings: Callable[[], Settings]
        quiet: Callable[[], Any]

    # ---------------------------------------------------------------- helpers
    def _put(self, key: str, handles: dict[str, Any]) -> None:
        """Remember the nodes a builder made, removing the previous ones of this group."""
        for n in [n for n in self.nodes if n.startswith(key)]:
            if n not in handles:
                with contextlib.suppress(Exception):
                    self.nodes[n].remove()
                del self.nodes[n]
        self.nodes.update(handles)

    def _send_queued(self, timeout_s: float = SEND_WAIT_S) -> None:
        """Hand what is queued for the browsers to their connections now (viser otherwise gathers messages into
        windows, and an atomic block started meanwhile holds them back with its own): waits until every open
        connection has taken them, at most ``timeout_s``."""
        with contextlib.suppress(Exception):
            self.server.flush()
            buffer = self.server._websock_server._broadcast_buffer  # viser's own; absent in another version
            last = buffer.message_counter - 1
            end = time.monotonic() + timeout_s
            while time.monotonic() < end and any(c < last for c in list(buffer.generator_cursors.values())):
                time.sleep(0.002)

    def maps_drawn_reported(self, _event: Any = None) -> None:
        """The page typed ``drawn <revision>`` into the hidden *Maps drawn* control
        (:data:`explorer.app.controls.DRAWN_SCRIPT`): a browser has drawn the maps of that revision."""
        import re

        m = re.fullmatch(r"drawn (\d+)", str(self.handles["maps_drawn"].value))
        if m is None:
            return
        with self._lock:
            self.maps_drawn = max(getattr(self, "maps_drawn", 0), int(m.group(1)))
            self._lock.notify_all()

    def view_drawn_reported(self, _event: Any = None) -> None:
        """The page typed ``drawn <n> <page>.<k>`` into the hidden *View drawn* control
        (:data:`explorer.app.controls.VIEW_DRAWN_SCRIPT`): a browser's 3D view has drawn the 3D batch ``n``."""
        import re

        m = re.fullmatch(r"drawn (\d+)(?: \S+)?", str(self.handles["view_drawn"].value))
        if m is None:
            return
        n, client = int(m.group(1)), getattr(_event, "client_id", None)
        with self._lock:
            self.view_drawn = max(getattr(self, "view_drawn", 0), n)
            self._views_drawn[client] = max(self._views_drawn.get(client, 0), n)
            self._lock.notify_all()

    def _mark_view_sent(self) -> int:
        """Number the 3D batch being sent (call inside its ``atomic`` block, last): the page reports it drawn."""
        self._view_sent = getattr(self, "_view_sent", 0) + 1
        self._view_deadline = time.monotonic() + VIEW_DRAWN_WAIT_S
        with contextlib.suppress(Exception):  # a controls double without the hidden control
            self.handles["view_drawn"].value = f"view {self._view_sent}"
        return self._view_sent

    def _wait_view_drawn(self, gen: int | None, timeout_s: float = VIEW_DRAWN_WAIT_S) -> None:
        """Wait until an open browser reported the 3D batch just sent as drawn (at most ``timeout_s``; not at all
        without a browser, and no longer once a newer request arrived).

        The update ends then, so that its time is that of the whole update on screen and a change made once the
        page is settled finds it idle: without a GPU a browser draws the 3D view in software and reads every 3D
        frame back to the CPU on the page's thread (70-170 ms a frame at 1400 x 900; viser draws several frames
        after each change), so maps sent meanwhile wait for those frames.  A newer request ends the wait at once
        (its maps go first: its update sends them before its own 3D batch)."""
        self._wait_reported("view_drawn", getattr(self, "_view_sent", 0), gen, timeout_s)

    def _wait_maps_drawn(self, gen: int | None, timeout_s: float = MAPS_DRAWN_WAIT_S) -> None:
        """Wait until an open browser reported the maps this update sent as drawn (at most ``timeout_s``; not at all
        without a browser, nor when the update sent no maps, nor once a newer request arrived).

        A browser without a GPU draws the 3D view in software: a frame takes 0.1-0.4 s of its page, and the maps
        of a SCOP change sent beside the 3D nodes waited one or two such frames before Plotly drew them.  The 3D
        part of the update follows the maps instead."""
        rev = getattr(self, "_maps_wait_rev", None)
        if rev is not None:
            self._wait_reported("maps_drawn", rev, gen, timeout_s)

    def _wait_reported(self, attr: str, rev: int, gen: int | None, timeout_s: float) -> None:
        """Wait until the page's report counter ``attr`` (``maps_drawn``, ``view_drawn``) reaches ``rev``: at most
        ``timeout_s``, not at all without a browser, and no longer once a newer request arrived or the app
        closes."""
        try:
            if not self.server.get_clients():
                return
        except Exception:
            return
        end = time.monotonic() + timeout_s
        with self._lock:
            while getattr(self, attr, 0) < rev:
                if (gen is not None and self._gen != gen) or getattr(self, "_closing", False):
                    return
                left = end - time.monotonic()
                if left <= 0:
                    return
                self._lock.wait(left)

    def _changed(self, group: str, key: Hashable) -> bool:
        if self._sent.get(group) == key:
            return False
        self._sent[group] = key
        return True

    def _frame_key(self, s: Settings) -> tuple:
        return (s.scene_key, s.sensor_distance, "auto" if s.auto_exaggeration else s.height_exaggeration,
                self._shows_refinement(s))

    def _shows_refinement(self, s: Settings) -> bool:
        """True when ``s`` shows the scene of ``explore --gcps`` (its Refinement folder draws trajectories) at the
        compressed sensor distance: the view is then framed to hold them (:meth:`_update_scene`)."""
        return (getattr(self, "refine_view", None) is not None and s.preset == getattr(self, "refine_label", None)
                and s.sensor_distance == "compressed")

    # ----------------------------------------------------------------- update
    def update(self, s: Settings, gen: int | None = None) -> dict[str, float]:
        """Recompute and redraw what ``s`` changed.

        Returns
        -------
        dict
            Stage timings in seconds: scene, methods, cloud, panels, selection, total (the
            scene and panels are up to date), sweep (accuracy-vs-density, after total);
            maps_drawn_wait: how long the update waited for a browser to report its maps painted
            (part of total; :meth:`_wait_maps_drawn`); view_drawn_wait: the same for its 3D batch
            (:meth:`_wait_view_drawn`).
        """
        times: dict[str, float] = {}
        t_start = time.perf_counter()
        self._check(gen)
        self._maps_wait_rev: int | None = None  # the maps this update sent, if any (_set_figure)
        for stage in ("scene", "methods", "panels"):
            t0 = time.perf_counter()
            getattr(self, f"_update_{stage}")(s, gen)
            times[stage] = time.perf_counter() - t0
            self._check(gen)
        # what the 3D view shows of the new results (the SCOPs, the cloud's colours, the selection, the labels)
        # reaches the browser as ONE batch after the panels: a browser's WebGL redraws the whole view for each
        # batch (in software, 0.1-0.5 s a frame, the page waiting), and the maps come first -- in a batch of their
        # own (a batch without 3D nodes is applied at once; one with them waits for the next 3D frame)
        t0 = time.perf_counter()
        self._send_queued()
        self._wait_maps_drawn(gen)
        times["maps_drawn_wait"] = time.perf_counter() - t0  # the browser's time, not the app's
        self._check(gen)
        with self.server.atomic():
            for stage in ("frame", "cloud", "selection"):
                t0 = time.perf_counter()
                getattr(self, f"_update_{stage}")(s, gen)
                times[stage] = time.perf_counter() - t0
                self._check(gen)
            self._layout_labels()
            self._mark_view_sent()
        t0 = time.perf_counter()
        self._send_queued()
        self._wait_view_drawn(gen)
        times["view_drawn_wait"] = time.perf_counter() - t0  # the browser's time, not the app's
        self.last_update_s = time.perf_counter() - t_start
        times["total"] = self.last_update_s
        if self.request_started is not None:
            times["since_request"] = time.monotonic() - self.request_started
        self.last_times = times
        scps = self.model.scps(s)
        self._status(self._done_text(self.runs, self.pending, scps), 100.0 if not self.pending else 70.0,
                     busy=bool(self.pending))
        with self._lock:
            if gen is not None:  # the scene and panels now show this request (see wait_update)
                self._completed_gen = max(self._completed_gen, gen)
                self._lock.notify_all()
            previews = any(r.preview for r in self.runs.values())
            if (gen is None or self._gen == gen) and not self.pending and not previews:
                self.request_started = None  # the whole update is on screen
        self._maps_shown(s)
        self._check(gen)
        t0 = time.perf_counter()
        self._update_sweep(s, gen)
        times["sweep"] = time.perf_counter() - t0
        if any(self.model.cached_fit(n, s) is not None for n in self.pending):
            # a training shown as pending landed while the sweep waited for it (the sweep at the shown SCOP count
            # shares its fit; a fit the update waits for redraws nothing when it lands): show it
            with self._lock:
                self._gen += 1
                self._lock.notify_all()
        self.last_times = times
        busy = self.fits is not None and self.fits.busy
        self._status(self._done_text(self.runs, self.pending, scps) + (" (training in the background)" if busy else ""),
                     100.0 if not busy else 85.0, busy=busy)
        return times

    def _update_scene(self, s: Settings, gen: int | None) -> None:
        """Scene, SCOPs and SCPs (the 3D view's ground, orbit and camera: :meth:`_update_frame`)."""
        m = self.model
        self._status(f"building scene {status_name(s.preset)}", 2)
        scene = m.scene(s)
        self._check(gen)
        m.scops(s)
        m.scps(s)
        self.scene = scene

    def _update_frame(self, s: Settings, gen: int | None) -> None:
        """The 3D view's frame on a new scene / frame: ground (DEM mesh), orbit and camera.

        Drawn in the 3D batch after the panels: the maps do not need it, and for a sensor without scanlines the
        drawn scene is an MPC fitted first (:meth:`_drawn_scene`, tenths of a second)."""
        B, m = self._B, self.model  # noqa: N806
        scene = m.scene(s)
        frame_key = self._frame_key(s)
        if self._changed("frame", frame_key):
            drawn = self._drawn_scene(s)  # the sensor, or for one without scanlines (an RPC) an MPC fitted to it
            auto, relief = B.auto_height_exaggeration(scene)
            factor = auto if s.auto_exaggeration else s.height_exaggeration
            distance: dict[str, float] = {}
            if self._shows_refinement(s):  # the trajectories inside the framed view: the track drawn nearer
                from explorer.scene3d.refine import framed_distance_factor

                distance["factor"] = framed_distance_factor(drawn, height_exaggeration=factor)
            self.frame = B.DisplayFrame.for_scene(drawn, sensor_distance=s.sensor_distance,
                                                  height_exaggeration=factor, **distance)
            n, dem_cells = B.ground_mesh_nodes(drawn)
            self.ground_text = ("Ground: the check points on the terrain (the footprint outlined in black)"
                                + ("; DEM heights" if dem_cells is not None else ""))
            if relief > 1.0 or factor != 1.0:
                how = (f"automatic: the terrain's {relief:.0f} m relief drawn at about "
                       f"{100 * B.RELIEF_SHARE:g} % of the footprint" if s.auto_exaggeration else "set by hand")
                self.ground_text += f"; heights exaggerated x{factor:g} ({how})"
            self.mark_unavailable_methods(scene)
            if drawn is not scene:
                self.ground_text += ("; the sensor has no scanlines (an RPC): the orbit, scanline planes and rays "
                                     "drawn are an MPC fitted to its lines of sight, every number is its own")
            if s.auto_exaggeration:
                with self.quiet():
                    self.handles["exaggeration"].value = factor
            with self.server.atomic():
                note = f"heights x{factor:g}" + (" (auto)" if s.auto_exaggeration else "") if factor != 1.0 else ""
                self._put("/ground", B.add_ground(self.server.scene, drawn, self.frame, n=n, note=note))
                # the check points' markers tile the whole footprint (SCP_COVER); the DEM mesh under them only
                # hid part of each marker -- a marker is drawn at its centre's depth, the decimated mesh cut
                # through it --: pale stripes across the residual colours.  Their cloud shows the relief.
                self.nodes["/ground/surface"].visible = False
                # the note may stand at any corner of the footprint (whichever keeps it clear)
                self.label_alternatives["/ground/note"] = tuple(self.frame.ground(B.footprint_corners(drawn)))
                self._put("/orbit", B.add_orbit(self.server.scene, drawn, self.frame))
            refine_view = getattr(self, "refine_view", None)  # explore --gcps: its trajectories, in the new frame
            if refine_view is not None:
                refine_view.draw_3d(visible=s.preset == getattr(self, "refine_label", None))
            refined = self._shows_refinement(s)
            self._frame_camera(drawn, (s.preset, s.sensor_distance, refined), refined=refined)
            fixed = s.preset in m.fixed_scenes
            with self.quiet():
                self.handles["sel_row"].max = float(scene.n_rows - 1)
                self.handles["sel_col"].max = float(scene.n_columns - 1)
                for key in ("relief", "rates", "jitter"):
                    self.handles[key].disabled = fixed
                # the dropdown may cut a long file name: its tooltip gives the one shown whole
                self.handles["preset"].hint = f"shown: {s.preset} -- a loaded file (named by file and sensor) or a " \
                    "synthetic preset"

    def _update_methods(self, s: Settings, gen: int | None) -> None:
        """Fit (cached / background) and evaluate every checked method on every SCP.

        In background mode a method whose full evaluation is projected to be slow
        (:meth:`ExplorerModel.needs_preview`) is shown first on the fixed seeded preview subset,
        named as such, while its full evaluation runs on the fit threads; when it lands the
        update runs again and shows it.  The final state never depends on the machine's load.
        """
        m = self.model
        scps = m.scps(s)
        runs: dict[str, MethodRun] = {}
        pending: dict[str, str] = {}
        self._eval_jobs = set()
        self._status("training" if any(registry()[n].needs_fit for n in s.methods) else "evaluating", 5)
        fits = self._get_fits([(n, None) for n in s.methods], s, 0, self.fit_wait_s, gen)
        for i, name in enumerate(s.methods):
            self._status(f"{name} ({i + 1}/{len(s.methods)}) on {len(scps):,} SCPs",
                         5 + 60 * i / max(len(s.methods), 1))
            rec = fits[(name, None)]
            if rec is None:
                pending[name] = self._pending_text(name, s)
            elif self.fits is not None and m.needs_preview(name, s, rec):
                runs[name] = m.evaluate(name, s, fit=rec, max_points=m.preview_points)
                key = ("evaluate", *m.eval_key(name, s))
                self._eval_jobs.add(key)
                self.fits.submit(key, lambda n=name, r=rec: m.evaluate(n, s, fit=r), 0, 0.5)  # type: ignore[misc]
            else:
                runs[name] = m.evaluate(name, s, fit=rec)
            self._check(gen)
        self.runs, self.pending = runs, pending

    def _update_cloud(self, s: Settings, gen: int | None) -> None:
        """The SCOPs and the SCP cloud in the 3D view, the cloud coloured by the colour method's row residual."""
        B, F = self._B, self._F  # noqa: N806
        scps, scops = self.model.scps(s), self.model.scops(s)
        if self._changed("scops", (self._frame_key(s), s.scop_density)):
            node = self.nodes.get("/points/scops")
            if node is not None and getattr(self, "_scops_frame", None) is self.frame:
                B.move_scops(node, self.frame, scops.ground)  # the same cloud on the new SCOPs (no new material)
            else:
                self._put("/points/scops", B.add_scops(self.server.scene, self.frame, scops.ground))
                self._scops_frame = self.frame
        cm = s.color_method
        run = self.runs.get(cm) if cm else None
        ev = run.evaluation if run is not None else None
        ev_key = run.key if run is not None and ev is not None else None
        limit = s.limit_px
        if ev is not None and s.colour_mode != "fixed":
            from explorer.panels import robust_limit

            limit = robust_limit(ev.residual_row)
        if not self._changed("scps", (self._frame_key(s), s.scp_count, cm, ev_key, limit)):
            return
        if ev is not None:
            idx_all, res_all = np.asarray(ev.evaluated_index), np.asarray(ev.residual_row)
        else:
            idx_all, res_all = np.arange(len(scps)), np.full(len(scps), np.nan)
        pos = F.decimation_index(len(idx_all), self.max_cloud_points)
        idx, res = idx_all[pos], res_all[pos]
        colors = diverging_rgb(res, limit) if ev is not None else np.full((len(idx), 3), 200, np.uint8)
        node = self.nodes.get("/points/scps")
        pos_key = (self._frame_key(s), id(scps), idx.tobytes())
        if node is not None and getattr(self, "_cloud_pos_key", None) == pos_key:
            node.colors = colors  # the same points: send their new colours only (not 50,000 positions again)
        else:
            self._put("/points/scps", B.add_points(self.server.scene, "/points/scps", self.frame, scps.ground[idx],
                                                   colors, size_km=B.point_size_km(self.frame, len(idx), B.SCP_COVER)))
            self._cloud_pos_key = pos_key
        self.cloud_index, self.cloud_residual = idx, res
        if ev is not None:
            what = f"coloured by **{cm}** row residual (+-{limit:.3g} px, magenta: no valid row)"
        elif cm in self.pending:
            what = f"grey until **{cm}** has trained"
        else:
            what = "grey (no method to colour by)"
        n_eval = len(idx_all)
        sub = (f" ({cm}: preview on a fixed seeded {n_eval:,}; every SCP is being evaluated)"
               if n_eval < len(scps) else "")
        dec = f"; the 3D view shows an evenly strided {len(idx):,} of {n_eval:,}" if len(idx) < n_eval else ""
        self.handles["cloud_text"].content = (f"SCPs: {len(scps):,}{sub}, {what}{dec}. SCOPs (gold): {len(scops)}. "
                                              f"{getattr(self, 'ground_text', '')}.")

    def _update_panels(self, s: Settings, gen: int | None) -> None:
        """Residual maps, timing bars and the summary table."""
        F, m = self._F, self.model  # noqa: N806
        scene, scps, scops = m.scene(s), m.scps(s), m.scops(s)
        runs, pending = self.runs, self.pending
        ok = {n: r.evaluation for n, r in runs.items() if r.evaluation is not None}
        maps_key = (tuple((n, runs[n].key) for n in ok), s.limit_px, s.colour_mode, s.component, s.diff,
                    s.show_scops, s.aggregate, s.scop_density, tuple(pending), self.methods_ready.is_set())
        if not self._changed("maps", maps_key):
            return
        src = self._source(s)
        stand_in = self._stand_in_map(s, src, scps) if src is not None and src.stand_in is not None else None
        if ok:
            maps, status = dict(ok), {n: runs[n].status for n in ok}
            labels = None
            if stand_in is not None:  # the stand-in's own error against the sensor, beside the methods' maps
                maps[STAND_IN_METHOD], status[STAND_IN_METHOD] = stand_in
                labels = {STAND_IN_METHOD: f"stand-in: {src.stand_in.label}"}
            fig = F.residual_maps(maps, scps, control=scops if s.show_scops else None, shape=scene.shape,
                                  limit_px=s.limit_px if s.colour_mode == "fixed" else None,
                                  mode=s.colour_mode, component=s.component, difference=s.diff,
                                  status=status, aggregate=s.aggregate, max_cells=self.max_map_cells,
                                  labels=labels, against=stand_in_truth(src.info if src is not None else None),
                                  cache=self._map_cache())
        else:
            fig = F.empty_figure("waiting for " + ", ".join(pending) if pending else self._no_method_text())
        self._set_figure("maps", fig)
        self._set_figure("timing", F.timing_bars(ok, colors=F.method_colors(self.method_names)) if ok else
                         F.empty_figure(self._no_method_text()))
        notes = []
        sub = [n for n in ok if runs[n].preview]
        if sub:
            notes.append(f"Preview: {', '.join(sub)} shown on a fixed seeded subset of "
                         f"{m.preview_points:,} SCPs while every SCP is evaluated (slow method); the maps are "
                         "replaced when it is done.")
        if ok:
            notes.append(f"Each map cell shows the {s.aggregate} of the residuals of the check points in it "
                         "(transparent: no check point). Click a cell to select its worst point in the 3D view.")
        if src is not None:
            notes.append(f"Truth: {src.info.get('truth')}; every residual is measured against its own "
                         "ground to image.")
            if src.stand_in is not None:
                notes.append(f"The map 'stand-in' is the error of the {src.stand_in.label} against it.")
            coverage = src.info.get("dem_coverage")
            if coverage:
                notes.append(f"The DEM covers {100 * coverage['fraction']:.1f} % of the image; {coverage['note']}.")
            if src.info.get("table_coverage"):
                notes.append(table_coverage_text(src.info["table_coverage"]).capitalize() + ".")
            if src.info.get("validity_note"):
                notes.append(f"RPC file: {src.info['validity_note']}.")
        left_out = self.model.scp_note(s)
        if left_out:
            notes.append(left_out.capitalize() + ".")
        self.handles["maps_note"].content = "  \n".join(f"*{t}*" for t in notes)
        text = summary_markdown(runs, len(scps))
        if pending:
            text += "\n" + "\n".join(f"- **{n}**: {t}" for n, t in pending.items())
        self.handles["summary"].content = text

    def _update_selection(self, s: Settings, gen: int | None) -> None:
        """The selected point, its scanline plane, ray and the colour method's search path."""
        sel = self.model.selection(s, self.runs)
        self.selection = sel
        label = f"selected: row {sel.exact_row:.2f}, col {sel.exact_col:.2f}"
        trace = None if sel.trace_rows is None else np.asarray(sel.trace_rows, dtype=np.float64).tobytes()
        # keyed by what is drawn, not by the colour method's result: a SCOP change that leaves the worst point and
        # its search path where they were sends nothing to the 3D view for them (the text below still follows)
        if self._changed("selection", (self._frame_key(s), sel.ground.tobytes(), sel.exact_row, trace, label)):
            self._draw_selection(s, sel, label)
        self._selection_text(sel)
        with self.quiet():
            if sel.source != "image point":
                self.handles["sel_row"].value = round(sel.exact_row * 2) / 2
                self.handles["sel_col"].value = round(sel.exact_col * 2) / 2

    def _draw_selection(self, s: Settings, sel: Selection, label: str) -> None:
        """The selected point's 3D nodes: its scanline plane (with the first / middle / last), ray, label and the
        colour method's search path."""
        B, m = self._B, self.model  # noqa: N806
        scene = m.scene(s)
        rows = np.array([0.0, (scene.n_rows - 1) / 2.0, scene.n_rows - 1.0, sel.exact_row])
        h_mean = scene.terrain.mean_height
        heights = np.array([h_mean, h_mean, h_mean, sel.ground[2]])
        names = ["first scanline (row 0)", "middle scanline", f"last scanline (row {scene.n_rows - 1})", ""]
        drawn = self._drawn_scene(s)
        with self.server.atomic():
            # the planes depend on the selected point's scanline only: a new method result (a SCOP change)
            # leaves them as they are (no new textures for the browser to upload and draw)
            if self._changed("scanlines", (self._frame_key(s), rows.tobytes(), heights.tobytes())):
                # the selected point's scanline plane filled, the first / middle / last outlined: a filled plane
                # covers much of the view and costs a software WebGL ~40 ms per frame at load 10
                self._put("/scanlines", B.add_scanline_planes(self.server.scene, drawn, self.frame, rows, heights,
                                                              names, filled=[len(rows) - 1]))
                # a scanline's label may stand at either end of its ground trace (whichever keeps it clear)
                ends = self.frame.ground(B.scanline_footprints(drawn, rows, heights).reshape(-1, 3)).reshape(-1, 2, 3)
                self.label_alternatives.update({f"/scanlines/labels/{i}": (ends[i, 1],)
                                                for i, n in enumerate(names) if n})
            self._put("/selected", B.add_selection(
                self.server.scene, drawn, self.frame, sel.ground, sel.exact_row, sel.trace_rows, label=label))

    def _update_sweep(self, s: Settings, gen: int | None) -> None:
        """Accuracy vs SCOP density: evaluate what is trained, queue the rest (low priority)."""
        F, m = self._F, self.model  # noqa: N806
        wanted = {m.fit_key(n, s) for n in s.methods}
        if s.sweep and s.methods:
            sweeps: dict[str, list] = {}
            jobs = [(n, d) for n in s.methods for d in
                    (SCOP_DENSITIES if registry()[n].needs_fit else SCOP_DENSITIES[:1])]
            wanted |= {m.fit_key(n, s, d) for n, d in jobs}
            fits = self._get_fits(jobs, s, 1, self.fit_wait_s, gen)
            self._check(gen)
            failed: dict[str, dict[int, str]] = {}
            for name in s.methods:
                failed[name] = {}
                sweeps[name] = m.sweep(name, s, get_fit=lambda d, n=name: fits.get((n, d)), failed=failed[name])
                self._check(gen)
            failed = {k: v for k, v in failed.items() if v}
            sweep_key = (s.scene_key, tuple((n, tuple((e.n_scops, e.rmse_px, e.dr_max_px) for e in v))
                                            for n, v in sweeps.items()), tuple(sorted(failed.items())))
            if self._changed("sweep", sweep_key):
                self.sweeps = sweeps
                self._set_figure("accuracy", F.accuracy_vs_density(sweeps, colors=F.method_colors(self.method_names),
                                                                   failed=failed))
        elif self._changed("sweep", ("off", bool(s.methods), self.methods_ready.is_set())):
            self.sweeps = {}
            self._set_figure("accuracy", F.empty_figure("sweep off" if s.methods else self._no_method_text()))
        if self.fits is not None:
            self.fits.keep(wanted | getattr(self, "_eval_jobs", set()))

    # ------------------------------------------------------------------- text
    def _no_method_text(self) -> str:
        return "no method checked" if self.methods_ready.is_set() else "loading the methods..."

    def _done_text(self, runs: dict[str, MethodRun], pending: dict[str, str], scps: PointSet) -> str:
        failed = [n for n, r in runs.items() if not r.ok and not r.unavailable]
        unavailable = [n for n, r in runs.items() if r.unavailable]
        sub = [n for n, r in runs.items() if r.preview]
        name = self.handles["preset"].value if self.scene is not None else ""
        whole = self.last_times.get("since_request", self.last_update_s)
        txt = f"{status_name(name)}: updated in {whole:.2f} s ({len(scps):,} SCPs)"
        if sub:
            txt += f"; preview on a seeded subset (full result computing): {', '.join(sub)}"
        if pending:
            txt += f"; training: {', '.join(pending)}"
        if failed:
            txt += f"; failed: {', '.join(failed)}"
        if unavailable:
            txt += f"; unavailable on this sensor (no scanlines; see the summary): {', '.join(unavailable)}"
        return txt

    def _map_cache(self) -> dict:
        """The residual maps' cell aggregates kept between updates (:func:`explorer.panels.figures.residual_maps`
        ``cache``): a SCOP change re-aggregates only the maps whose evaluation changed.  Bounded: emptied when it
        holds more than 64 maps."""
        cache = self.__dict__.setdefault("_map_cells", {})
        if len(cache) > 64:
            cache.clear()
        return cache

    def _set_figure(self, key: str, fig: Any) -> None:
        h = self.handles[key]
        meta = fig.layout.meta
        if key == "maps":  # a revision the page reports once it has drawn them (maps_drawn_reported)
            self._maps_revision = getattr(self, "_maps_revision", 0) + 1
            meta = {**(meta if isinstance(meta, dict) else {}), "revision": self._maps_revision}
            fig.layout.meta = meta
            self._maps_wait_rev = self._maps_revision
        # the figure and its height in one batch: the browser applies them in one render, one Plotly.react (sent
        # apart, a new height -- the maps' legend grows or shrinks with the statuses shown -- drew the whole
        # figure twice)
        with self.server.atomic():
            h.figure = fig
            if isinstance(meta, dict) and "height_over_width" in meta:
                # viser's client draws height = width * aspect (its docstring says width/height)
                h.aspect = float(meta["height_over_width"])

    def _selection_text(self, sel: Selection) -> None:
        lines = [f"**{sel.source}**: row {sel.exact_row:.3f}, col {sel.exact_col:.3f}, height {sel.ground[2]:.1f} m"]
        if sel.method is not None and sel.est_row is not None:
            err = sel.est_row - sel.exact_row
            lines.append(f"{sel.method}: row {sel.est_row:.4f} (error {err:+.3g} px)")
            if sel.trace_rows is not None and len(sel.trace_rows):
                tr = sel.trace_rows
                shown = " -> ".join(f"{r:.2f}" for r in tr[:12]) + (" -> ..." if len(tr) > 12 else "")
                lines.append(f"visited {len(tr)} scanlines: {shown}")
        self.handles["sel_text"].content = "  \n".join(lines)

    # ----------------------------------------------------------------- labels
    LABEL_PRIORITY = ("/ground/note", "/selected/label", "/refine/label", "/scanlines/labels/", "/orbit/flight_label",
                      "/orbit/track_label", "/selected/trace_labels/")
    """Which labels yield to which when they would overlap (earlier wins)."""

    def _label_views(self) -> list[tuple[Any, Any]]:
        """(name, :class:`explorer.scene3d.labels.View`) of every open browser's framed view (its own canvas
        and the pose the app framed for it), or of the default canvas while no browser reported its canvas."""
        from explorer.scene3d.camera import DEFAULT_CANVAS_PX, VIEW_FOV_Y
        from explorer.scene3d.labels import View

        views = []
        canvases = self.client_canvases
        with contextlib.suppress(Exception):
            for cid in sorted(self.server.get_clients(), key=str):
                pose, canvas = self.client_poses.get(cid), canvases.get(cid)
                if pose is not None and canvas is not None:
                    views.append((cid, View(np.array(pose[0]), np.array(pose[1]), *canvas)))
        if not views and self.camera_pose is not None:
            pos, look, _ = self.camera_pose
            views.append(("default", View(np.array(pos), np.array(look), VIEW_FOV_Y, *map(float, DEFAULT_CANVAS_PX))))
        return views

    def _layout_labels(self) -> None:
        """Anchor every 3D label so that, in the framed view of every open browser's canvas (the default
        canvas before one reported its own), none is clipped by the view's edge or stacked on another
        (:func:`explorer.scene3d.labels.place_labels_in_views`); a label that fits nowhere is hidden.  Each
        keeps its builder's anchor when that fits.  The label of a refinement's trajectories
        (:meth:`explorer.app.refine_view.RefineView.label_nodes`, while they are shown) is laid out with the
        others; its view calls this again when it redraws them, and a browser's framing does too (from their
        own threads: one layout at a time)."""
        with self._label_lock:
            self._layout_labels_now()

    def _layout_labels_now(self) -> None:
        from explorer.scene3d.labels import Label, place_labels_in_views

        if self.camera_pose is None:
            return
        prefs = self.__dict__.setdefault("_label_prefs", {})
        found = []
        nodes = dict(self.nodes)
        alternatives = dict(getattr(self, "label_alternatives", {}))
        refine_view = getattr(self, "refine_view", None)
        if refine_view is not None:
            for key, (handle, points) in refine_view.label_nodes().items():
                nodes[key], alternatives[key] = handle, points
        for key, handle in nodes.items():
            if not (hasattr(handle, "anchor") and hasattr(handle, "text")):
                continue
            if prefs.get(key, (None,))[0] is not handle:  # a new label: its builder's anchor and point come first
                prefs[key] = (handle, str(handle.anchor), np.asarray(handle.position, dtype=np.float64).copy())
            rank = next((i for i, p in enumerate(self.LABEL_PRIORITY) if key.startswith(p)), len(self.LABEL_PRIORITY))
            found.append((rank, key, handle))
        found.sort(key=lambda t: (t[0], t[1]))
        labels = [Label(key, str(h.text), prefs[key][2], (prefs[key][1],), float(getattr(h, "font_screen_scale", 1.0)),
                        tuple(alternatives.get(key, ()))) for _, key, h in found]
        views = self._label_views()
        # (a label redrawn with the same text and point is a new handle: it needs the layout's anchor too)
        layout_key = (tuple((name, v.position.tobytes(), v.look_at.tobytes(), v.fov_y, v.width, v.height)
                            for name, v in views),
                      tuple((lab.key, lab.text, lab.point.tobytes(), id(h)) for lab, (_, _, h)
                            in zip(labels, found, strict=True)))
        if not self._changed("labels", layout_key):
            return
        placed = place_labels_in_views(labels, [v for _, v in views])
        self.label_layout = {k: None if v is None else (v[0], v[1][0], v[2]) for k, v in placed.items()}
        self.label_boxes = {name: {k: None if v is None else v[1][i] for k, v in placed.items()}
                            for i, (name, _) in enumerate(views)}
        for _, key, handle in found:
            got = placed.get(key)
            with contextlib.suppress(Exception):
                if got is None:
                    if handle.visible:
                        handle.visible = False
                else:
                    if handle.anchor != got[0]:
                        handle.anchor = got[0]
                    if not np.allclose(handle.position, got[2], rtol=0, atol=1e-9):
                        handle.position = got[2]
                    if not handle.visible:
                        handle.visible = True

    # ----------------------------------------------------------------- camera
    def _camera_for(self, scene: Scene, refined: bool = False) -> tuple[tuple, tuple, float]:
        """(position, look_at, far) framing the footprint (and as much of the displayed track as fits) for
        the default canvas (:func:`explorer.scene3d.camera.frame_footprint`); a browser that reported its
        canvas gets a pose for its own aspect (:meth:`_pose_for_client`).  ``refined``: the view also holds
        the trajectories a refinement draws around the track (:func:`explorer.scene3d.refine.trajectory_envelope`,
        the track drawn near enough by :func:`explorer.scene3d.refine.framed_distance_factor`)."""
        frame, B = self.frame, self._B  # noqa: N806
        ground = frame.ground(B.footprint_outline(scene, per_edge=16).reshape(-1, 3))
        _, pos = B.track_positions(scene, 9)
        include = None
        if refined:  # explore --gcps: the trajectories in the view too
            from explorer.scene3d.refine import trajectory_envelope

            include = trajectory_envelope(frame.sensor(pos), frame.diagonal_km)
        self._framing = (ground, frame.sensor(pos), include)
        pose = self._frame_pose()
        return tuple(float(v) for v in pose.position), tuple(float(v) for v in pose.look_at), pose.far

    def _frame_pose(self, aspect: float | None = None, fov_y: float | None = None) -> Any:
        """:func:`explorer.scene3d.camera.frame_footprint` of the current framing for a canvas (default: the
        default canvas): with the points it must include (a refinement's trajectories) where the footprint keeps
        at least half of the view with them, else the footprint alone."""
        from explorer.scene3d.camera import DEFAULT_ASPECT, VIEW_FOV_Y, frame_footprint

        ground, track, include = self._framing
        a = DEFAULT_ASPECT if aspect is None else float(aspect)
        f = VIEW_FOV_Y if fov_y is None else float(fov_y)
        if include is not None:
            with contextlib.suppress(ValueError):
                return frame_footprint(ground, track, include=include, aspect=a, fov_y=f)
        return frame_footprint(ground, track, aspect=a, fov_y=f)

    def _pose_for_client(self, client: Any) -> tuple[tuple, tuple, float, float]:
        """(position, look_at, far, near) framing the footprint in ``client``'s canvas (its reported aspect
        and field of view; the default canvas until it reported one)."""
        from explorer.scene3d.camera import DEFAULT_ASPECT, VIEW_FOV_Y

        cam = client.camera
        aspect, fov = DEFAULT_ASPECT, VIEW_FOV_Y
        canvas = None
        with contextlib.suppress(Exception):  # a camera that has not reported yet raises / has no size
            w, h, f = float(cam.image_width), float(cam.image_height), float(cam.fov)
            if w > 0 and h > 0 and 0 < f < np.pi:
                aspect, fov, canvas = w / h, f, (f, w, h)
        pose = self._frame_pose(aspect=aspect, fov_y=fov)
        out = (tuple(float(v) for v in pose.position), tuple(float(v) for v in pose.look_at), pose.far, pose.near)
        cid = getattr(client, "client_id", id(client))
        earlier = self.client_poses.get(cid)
        if earlier is not None and earlier[0] != out[0]:  # poses sent before: a report at one of them is stale
            sent = self._poses_sent.setdefault(cid, [])
            sent[:] = [*sent[-(SENT_POSES_KEPT - 1):], earlier[0]]
        self.client_poses[cid] = out
        if canvas is not None:  # the canvas this pose frames: the labels are laid out in it
            self.client_canvases[cid] = canvas
        return out

    def _apply_camera(self, clients: list[Any]) -> None:
        if self.camera_pose is None:
            return
        for client in clients:
            with contextlib.suppress(Exception):
                pos, look, far, near = self._pose_for_client(client)
                with client.atomic():
                    client.camera.far = far
                    client.camera.near = near
                    client.camera.position = pos  # viser moves look_at with the position: set it after
                    client.camera.look_at = look

    def _client_camera_reported(self, client: Any) -> None:
        """A browser's camera reported (its canvas size among it): frame the footprint for that canvas once
        per scene, and again when the canvas changes shape (the panels dock after the first report) while
        the camera is still where the framing put it -- once the user has moved it, it is left alone.

        viser calls this in a pool thread per report, so two reports' calls can run at once: the decision, the
        pose and its sending are one step under ``_camera_lock``. Interleaved (seen under load, a CTX ISD's
        browser test), the call for the first report (the wide canvas before the panels docked) computed its pose,
        the call for the next (the docked canvas) computed and sent its own, recorded as this browser's, and
        then the first one's pose went out last: the browser stayed at a pose that was neither the recorded one
        nor the initial camera, which a young browser's reports may carry, so nothing framed it again."""
        framed = False
        with contextlib.suppress(Exception), self._camera_lock:
            cam = client.camera
            w, h = float(cam.image_width), float(cam.image_height)
            if self.camera_pose is None or not (w > 0 and h > 0):
                return
            key = self._sent.get("camera")
            done = self._framed_clients.get(client.client_id)
            if done is not None and done[0] == key:
                # at a pose the app gave it: the one framed for this browser, or the server's initial camera (a
                # report sent before the browser's own framing arrived carries that one)
                ours = self.client_poses.get(client.client_id)
                at_ours, at_initial = (p is not None and np.allclose(cam.position, p[0], atol=1e-6, rtol=1e-6)
                                       and np.allclose(cam.look_at, p[1], atol=1e-6, rtol=1e-6)
                                       for p in (ours, self.camera_pose))
                # just connected: its reports may still carry the pose before ours (the page lays out its
                # panels in its first seconds); later, only a camera the user has not moved is reframed
                young = time.monotonic() - self._client_since.get(client.client_id, -np.inf) < CANVAS_SETTLE_S
                # back at the server's initial camera after its own framing was sent: a late report of the pose
                # the page started with overwrote it (seen under load) -- frame it again, whatever its shape
                lost = ours is not None and at_initial and not at_ours
                # at a pose framed for it EARLIER (another canvas shape): that framing reached the browser after
                # the newer one (seen under load in CI: the wide canvas's pose applied after the docked one's) --
                # not a user's move, which never lands within 1e-6 on a pose the app sent: frame it again
                lost = lost or (not at_ours and any(
                    np.allclose(cam.position, p, atol=1e-6, rtol=1e-6)
                    for p in self._poses_sent.get(client.client_id, ())))
                if not lost and (not (at_ours or at_initial or young) or abs(done[1] - w / h) <= 1e-3 * done[1]):
                    return
            self._framed_clients[client.client_id] = (key, w / h)
            self._apply_camera([client])
            framed = True
        if framed:  # the labels fit this browser's view too (outside the lock: it takes its own)
            with contextlib.suppress(Exception):
                self._layout_labels()

    def _frame_camera(self, scene: Scene, key: Hashable, *, refined: bool = False) -> None:
        """Point the initial camera at the footprint and, on a new scene, every open browser's; ``refined``: the
        view holds a refinement's trajectories too (:meth:`_camera_for`)."""
        pos, look, far = self._camera_for(scene, refined)
        self.camera_pose = (pos, look, far)
        self.server.initial_camera.far = far
        self.server.initial_camera.look_at = look
        self.server.initial_camera.position = pos
        if self._changed("camera", key):
            with self._camera_lock:  # not between a camera report's decision and its sending
                self._apply_camera(list(self.server.get_clients().values()))
                for cid, client in self.server.get_clients().items():
                    with contextlib.suppress(Exception):
                        cam = client.camera
                        self._framed_clients[cid] = (key, float(cam.image_width) / float(cam.image_height))

    def reset_view(self) -> None:
        """Frame the current footprint and track again in every open browser."""
        if self.camera_pose is not None:
            with self._camera_lock:  # not between a camera report's decision and its sending
                self._apply_camera(list(self.server.get_clients().values()))

    # ----------------------------------------------------------------- export
    def export_bytes(self, s: Settings | None = None) -> bytes:
        """A zip of ``summary.json``, ``residuals.csv`` and ``panels.html`` for the current settings
        (every SCP, no subsample; :func:`explorer.app.export.export_files`)."""
        from explorer.app.export import export_files

        s = s or self.settings()
        src = self._source(s)
        files = export_files(self.model.scene(s), s, source=self._source_info(s), seed=self.model.seed,
                             fits={n: self.model.fit(n, s) for n in s.methods},
                             sweep_fit=lambda n, d: self.model.fit(n, s, d, purpose=SWEEP_PURPOSE),
                             stand_in=src.stand_in if src is not None else None,
                             native_pixels=src is not None and src.kind == "isd")
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            for name, data in files.items():
                zf.writestr(zipfile.ZipInfo(name, date_time=(2000, 1, 1, 0, 0, 0)), data)
        return buf.getvalue()

    def mark_unavailable_methods(self, scene: Any) -> None:
        """Mark in the method list the methods ``scene`` cannot serve, with the reason
        (:func:`explorer.methods.unavailable_reason`: a search method on an RPC, which has no scanlines)."""
        boxes = self.handles.get("method_boxes") or {}
        reg = registry()
        self.controls.mark_unavailable({n: reg[n].unavailable_reason(scene) if n in reg else None for n in boxes})

    def _drawn_scene(self, s: Settings) -> Any:
        """The scene the 3D view draws: the sensor itself, or for a loaded sensor without line geometry (an RPC)
        its :meth:`explorer.sources.Source.display_scene` (an MPC fitted to it, drawing only)."""
        scene = self.model.scene(s)
        src = self._source(s)
        return src.display_scene() if src is not None and src.scene is scene else scene

    def _source(self, s: Settings) -> Any:
        """The loaded file source shown by ``s`` (an :class:`explorer.sources.Source`), or None for a preset."""
        return next((src for src in getattr(self, "sources", []) if src.label == s.preset), None)

    def _stand_in_map(self, s: Settings, src: Any, scps: Any) -> tuple[Any, Any]:
        """The stand-in's evaluation against the sensor on the current SCPs (cached per SCP set)."""
        key = (s.preset, int(s.scp_count))
        cache = self.__dict__.setdefault("_stand_in_cache", {})
        if key not in cache:
            cache.clear()
            cache[key] = evaluate_stand_in(src.stand_in, scps, STAND_IN_METHOD)  # SCPs: the sensor's points
        return cache[key]

    def _source_info(self, s: Settings) -> dict:
        for src in getattr(self, "sources", []):
            if src.label == s.preset:
                return src.to_dict()
        return {"kind": "preset", "label": s.preset, "relief_m": s.relief_m,
                "attitude_rate_scale": s.attitude_rate_scale, "jitter_scale": s.jitter_scale}

    def export_to_client(self, client: Any = None) -> None:
        """Compute the export (in a thread) and send the zip to ``client`` (or every client)."""
        s = self.settings()

        def run() -> None:
            self._status("exporting every SCP (no subsample)...", None)
            try:
                data = self.export_bytes(s)
            except Exception as exc:  # shown, never fatal
                self._status(f"export failed: {type(exc).__name__}: {exc}", None, busy=False)
                return
            target = client if client is not None else self.server
            target.send_file_download("pushbroom-export.zip", data, save_immediately=True)
            self.exports += 1
            self._status(f"exported {len(data):,} bytes (pushbroom-export.zip)", None, busy=False)

        if self.background:
            threading.Thread(target=run, name="explorer-export", daemon=True).start()
        else:
            run()


__all__ = ["Superseded", "Views", "markdown_literal", "short_name", "status_name"]
