"""The explorer's GUI on a viser server: :class:`ExplorerApp`.

The app owns the controls (:mod:`explorer.app.controls`), a worker thread that recomputes
what the controls changed (requests are debounced -- a slider drag sends dozens -- and the
newest wins), the fit threads (:class:`explorer.app.jobs.FitPool`) and the drawing
(:class:`explorer.app.views.Views`: the 3D scene through :mod:`explorer.scene3d.builders`,
the Plotly panels through :mod:`explorer.panels.figures`).  All numbers come from
:class:`explorer.app.model.ExplorerModel`.  Usage: ``docs/explorer.md``.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
import traceback
from collections.abc import Hashable, Iterator, Sequence
from typing import Any

import numpy as np

from explorer.app.controls import Controls
from explorer.app.jobs import FitPool
from explorer.app.model import (
    DEFAULT_METHODS,
    SWEEP_PURPOSE,
    Evaluation,
    ExplorerModel,
    FitRecord,
    MethodRun,
    Selection,
    Settings,
    control_default,
    safe_available,
)
from explorer.app.views import VIEW_DRAWN_WAIT_S, Superseded, Views
from explorer.methods import registry
from explorer.presets import default_preset_id, preset_ids
from explorer.scene import Scene

DEBOUNCE_S = 0.25
"""A request waits until the controls have been still this long (a slider drag sends a value per
frame; only the last is computed)."""

BROWSER_CATCH_UP_S = 5.0
"""After the first complete maps are sent, the held work (the long trainings, the accuracy sweep) waits until every
open browser has taken in what was sent (:meth:`ExplorerApp._browsers_caught_up`), at most this long."""

_CATCH_UP_KEY = "pushbroom-explorer-catch-up"
"""The localStorage key read back from each browser by :meth:`ExplorerApp._browsers_caught_up` (never written)."""


AMBIENT_INTENSITY = 1.2
"""The ambient light that stands in for the environment map on the few lit objects (the selected point's sphere,
the flight-direction arrow, the sensor frames): their sides away from the default lights stay readable."""


def configure_lighting(scene: Any) -> None:
    """Light the 3D view for a browser that draws WebGL in software (no GPU: headless Chromium, many VMs).

    viser's defaults cost such a browser seconds: its environment map (an HDR image turned into a
    pre-filtered cube map by a 256-sample GGX convolution, compiled and run on the first frame that shows a lit
    object: 4.9-7.3 s of one frame in Chrome traces at load 3-6, the first SCOP change after loading waiting
    behind it) and its shadows (three cascaded shadow maps rendered every frame, every material compiled with
    shadow sampling).  The explorer's points, lines, planes and labels are unlit; the few lit objects get the two
    default directional lights and an ambient light instead.  ``scene``: a ``viser.SceneApi``.
    """
    scene.configure_environment_map(None)
    scene.configure_default_lights(True, cast_shadow=False)
    scene.add_light_ambient("/lights/ambient", intensity=AMBIENT_INTENSITY)


class ExplorerApp(Views):
    """The explorer's GUI on a viser server.

    Parameters
    ----------
    server : viser.ViserServer
    preset : str, optional
        Scene shown first: a preset id or the label of one of ``sources`` (default: the first
        source, else the default preset).
    methods : sequence of str, optional
        Methods checked at start (default: :data:`DEFAULT_METHODS` that are registered).
    scp_count, scop_density : int
    background : bool
        True (interactive): recompute in a worker thread, newest request wins, and train
        learned methods in a :class:`FitPool` thread -- an update waits at most
        ``fit_wait_s`` for a fit, shows the other methods, and redraws when the fit lands.
        False: every request (every ``.value`` assignment) recomputes inline, fits
        included, and returns with the scene updated (tests, scripts).
    model : ExplorerModel, optional
    max_cloud_points : int
        At most this many SCPs are sent to the 3D view (an evenly strided subset, named in
        the GUI).
    max_map_cells : int
        At most this many cells per residual map (:func:`explorer.panels.raster.cell_grid`).
    sweep : bool
        Compute the accuracy-vs-density sweep (checkbox, can be changed in the GUI).
    fit_wait_s : float
        How long an update waits for a fit in background mode before showing it as pending.
    sources : sequence of explorer.sources.Source, optional
        Loaded scenes (real sensors) offered in the scene dropdown before the presets.
    debounce_s : float
        Background mode: start computing once the controls have been still this long.
    compile_progress : explorer.kernel_cache.CompileProgress, optional
        Follows numba compiling the package's kernels (installed by the caller); while anything compiles,
        the panel shows a line "Compiling kernels for first use k/n" and a progress bar above the status
        line, removed when the compilations of an update are over (``compile_log`` keeps the texts shown).
    """

    def __init__(
        self,
        server: Any,
        *,
        preset: str | None = None,
        methods: tuple[str, ...] | list[str] | None = None,
        scp_count: int = 50_000,
        scop_density: int = 100,
        background: bool = True,
        model: ExplorerModel | None = None,
        max_cloud_points: int = 50_000,
        max_map_cells: int = 15_000,
        sweep: bool = True,
        fit_wait_s: float = 0.5,
        sources: Sequence[Any] = (),
        debounce_s: float = DEBOUNCE_S,
        compile_progress: Any = None,
    ) -> None:
        import viser  # noqa: F401  (the GUI layer; the model never needs it)

        from explorer.panels import figures as F  # noqa: N812
        from explorer.scene3d import builders as B  # noqa: N812

        self._F, self._B = F, B
        self.server = server
        self.sources = [s for s in sources if s.scene is not None]
        self.model = model or ExplorerModel()
        for src in self.sources:
            self.model.fixed_scenes[src.label] = src.scene
        self.background = background
        self.debounce_s = debounce_s
        self.max_cloud_points = max_cloud_points
        self.max_map_cells = max_map_cells
        self.fit_wait_s = fit_wait_s
        self.nodes: dict[str, Any] = {}
        self.runs: dict[str, MethodRun] = {}
        self.pending: dict[str, str] = {}
        self.sweeps: dict[str, list[Evaluation]] = {}
        self.selection: Selection | None = None
        self.frame = None
        self.scene: Scene | None = None
        self.cloud_index: np.ndarray | None = None
        self.cloud_residual: np.ndarray | None = None
        self.last_update_s: float | None = None
        self.request_started: float | None = None
        """``time.monotonic()`` of the first request not yet fully shown (the status line states the time
        from it to the scene and maps on screen, the whole update; None when idle)."""
        self.last_times: dict[str, float] = {}
        self.errors: list[str] = []
        self.url: str | None = None
        self.startup_s: float | None = None
        self.camera_pose: tuple | None = None
        """(position, look_at, far) of the last framing for the default canvas, display km."""
        self.client_poses: dict[Any, tuple] = {}
        """Per browser (client id): (position, look_at, far, near) of its last framing, for its own canvas."""
        self._framed_clients: dict[Any, tuple] = {}
        self._client_since: dict[Any, float] = {}
        self._poses_sent: dict[Any, list] = {}  # per browser: earlier framings sent to it (a report at one is stale)
        self._camera_lock = threading.RLock()
        """Held while a framing is decided and sent: viser runs each camera report's callback in its own pool
        thread, and two of them interleaved sent a browser two poses in the other order
        (:meth:`_client_camera_reported`)."""
        self.label_layout: dict[str, Any] = {}
        """Per 3D label: (anchor, box px, point), the box in the first view laid out (the first open browser's,
        else the default canvas's; :meth:`_label_views`), None when hidden."""
        self.label_boxes: dict[Any, dict[str, Any]] = {}
        """Per view laid out (a browser's client id, or "default"): each label's box (x0, y0, x1, y1) px, None
        when hidden."""
        self.client_canvases: dict[Any, tuple[float, float, float]] = {}
        """Per browser: (fov_y, width, height) of the canvas its last framing was made for."""
        self._label_lock = threading.RLock()
        self.label_alternatives: dict[str, tuple] = {}
        """Other points a 3D label may stand at (a scanline's label: the other end of its trace)."""
        """Per browser: (camera key, canvas aspect) of its last framing."""
        self.exports = 0
        self._sent: dict[str, Hashable] = {}
        self._local = threading.local()
        self._lock = threading.Condition()
        self._gen = 0
        self._done_gen = 0
        self._completed_gen = 0
        self._busy = False
        self._closing = False
        self._waiting_for: set = set()
        self._last_trigger = 0.0
        self._last_request = 0.0
        self._worker: threading.Thread | None = None
        self.fits: FitPool | None = None
        self.hold_long_fits = True
        """Until the first maps are on screen, long trainings (``long_fit`` methods: an MLP, torch imported) wait
        in the fit pool: running beside the first update they took the CPU (and the interpreter) from it."""
        self.trimmer: Any = None
        """Set by :func:`explorer.app.server.serve`: hands freed memory back after browsers leave."""
        self.compile_progress = compile_progress
        self.compile_log: list[str] = []
        """Every text the compiling line showed, in order ("" when it was removed)."""

        self.method_names: list[str] = []
        self.methods_ready = threading.Event()
        self._methods_gen = 0
        wanted = list(methods) if methods is not None else None
        labels = [s.label for s in self.sources]
        scene_ids = labels + [p for p in preset_ids() if p not in labels]
        first = preset or (labels[0] if labels else default_preset_id())
        self.controls = Controls(self, server.gui, scene_ids=scene_ids, scene_id=first, scp_count=scp_count,
                                 scop_density=scop_density, sweep=sweep)
        self.handles: dict[str, Any] = self.controls.handles
        """The controls' handles by key (owned by :attr:`controls`)."""
        self.panel = self.controls.panel
        self.maps_drawn = 0
        """The newest maps revision (``layout.meta["revision"]``) a browser reported as drawn."""
        self.handles["maps_drawn"].on_update(self.maps_drawn_reported)
        self.view_drawn = 0
        """The newest 3D batch (its number, :meth:`_mark_view_sent`) a browser reported as drawn."""
        self._view_sent = 0
        self._views_drawn: dict[Any, int] = {}
        """The newest 3D batch each browser (by viser client id) reported drawn."""
        self._view_deadline = 0.0
        """Until then (``time.monotonic()``) the app counts as busy while no browser reported the newest 3D batch
        drawn (see :meth:`wait_idle`)."""
        self.handles["view_drawn"].on_update(self.view_drawn_reported)
        if compile_progress is not None:
            compile_progress.observers.append(self._show_compiling)
        self.server.scene.set_up_direction("+z")
        configure_lighting(self.server.scene)
        self.server.initial_camera.near = 0.001
        self.server.initial_camera.far = 5000.0
        with contextlib.suppress(Exception):  # frame each browser for its own canvas once it reports it
            self.server.on_client_connect(self._client_connected)
        if background:
            # draw the scene at once; import the method modules (torch...) meanwhile
            self.fits = FitPool(self._lock, self._fit_done)
            self._worker = threading.Thread(target=self._work, name="explorer-worker", daemon=True)
            self._worker.start()
            self.request_update(debounce=False)  # no slider moves yet: nothing to wait for
            threading.Thread(target=self._discover_methods, args=(wanted,), name="explorer-discover",
                             daemon=True).start()
        else:
            self._discover_methods(wanted)

    async def _client_connected(self, client: Any) -> None:
        """Listen to a new browser's camera reports (each one frames it for its canvas).

        A coroutine, so that viser runs it inline, before it hands the browser's FIRST camera report to the
        camera callbacks: viser counts a browser as connected on that report, runs a plain connect callback in
        its thread pool and goes straight on to the report's camera callbacks -- usually before the pool thread
        had registered ours. That report was lost, and a browser whose canvas never changes shape sends no
        other: it stayed at the server's initial camera, never framed (seen in CI, a wide window). Only quick,
        non-blocking work here: it runs on viser's event loop."""
        self._client_since[client.client_id] = time.monotonic()
        # the page draws the state it was sent on connecting (the buffer replayed): idle once it has drawn it
        self._view_deadline = max(self._view_deadline, time.monotonic() + VIEW_DRAWN_WAIT_S)
        client.camera.on_update(lambda cam: self._client_camera_reported(cam.client))

    def _discover_methods(self, wanted: list[str] | None) -> None:
        """Import the method modules, add a checkbox per registered method, then update."""
        names, err = safe_available()
        if err:
            self.errors.append(err)
        wanted = wanted if wanted is not None else [m for m in DEFAULT_METHODS if m in names]
        unknown = [m for m in wanted if m not in names]
        if unknown:
            msg = f"unknown method(s) {unknown}; available: {', '.join(names)}"
            if not self.background:
                raise KeyError(msg)
            self.errors.append(msg)
            print(f"pushbroom explorer: {msg}", file=sys.stderr, flush=True)
            wanted = [m for m in wanted if m in names]
        h = self.handles

        def hint(name: str) -> str:
            cls = registry()[name]
            return f"{cls.label} -- {cls.reference}"

        self.controls.add_method_boxes(names, wanted, hint)
        if self.scene is not None:
            self.mark_unavailable_methods(self.scene)
        order = wanted + [n for n in names if n not in wanted]
        with self.quiet():
            self.controls.set_method_options(wanted)
            self.controls.set_mlp_defaults(control_default("layers", order, 1), control_default("neurons", order, 10))
        h["methods_note"].content = ("" if not err else f"*some method modules failed to load: {err}*")
        self.method_names = names
        self._methods_gen = self.request_update(debounce=False)
        self.methods_ready.set()

    def wait_methods(self, timeout: float = 120.0) -> int:
        """Block until the methods are loaded; returns the generation of the update that first
        uses them (for :meth:`wait_update`), 0 on timeout."""
        return self._methods_gen if self.methods_ready.wait(timeout) else 0

    def pick_index(self) -> int | None:
        """The SCP index typed into (or clicked into) the *Picked SCP* control, if any."""
        return self.controls.pick_index()

    @contextlib.contextmanager
    def quiet(self) -> Iterator[None]:
        """Programmatic GUI changes inside this block (this thread) do not trigger updates."""
        old = getattr(self._local, "quiet", False)
        self._local.quiet = True
        try:
            yield
        finally:
            self._local.quiet = old

    def is_quiet(self) -> bool:
        """True inside :meth:`quiet` on this thread (the controls' callbacks then request nothing)."""
        return bool(getattr(self._local, "quiet", False))

    def checked_methods(self) -> list[str]:
        return self.controls.checked_methods()

    def settings(self) -> Settings:
        """The current control values."""
        h = self.handles
        methods = tuple(self.checked_methods())
        cm = h["color_method"].value
        pick = self.pick_index()
        if h["sel_mode"].value == "image point":
            sel: tuple = ("image", float(h["sel_row"].value), float(h["sel_col"].value))
        elif h["sel_mode"].value == "picked SCP" and pick is not None:
            sel = ("scp", pick)
        else:
            sel = ("worst",)
        fixed = h["preset"].value in self.model.fixed_scenes  # a loaded file: the preset sliders do not apply
        a, b = h["diff_a"].value, h["diff_b"].value
        diff = (a, b) if a in methods and b in methods and a != b else None
        return Settings(
            preset=h["preset"].value, relief_m=0.0 if fixed else float(h["relief"].value),
            attitude_rate_scale=1.0 if fixed else round(float(h["rates"].value), 6),
            jitter_scale=1.0 if fixed else round(float(h["jitter"].value), 6), scop_density=int(h["density"].value),
            scp_count=int(h["scps"].value), methods=methods,
            color_method=cm if cm in methods else (methods[0] if methods else None),
            mlp_layers=int(h["layers"].value), mlp_neurons=int(h["neurons"].value),
            limit_px=float(h["limit"].value), colour_mode=h["colour_mode"].value,
            component=h["component"].value, aggregate=h["aggregate"].value, diff=diff,
            show_scops=bool(h["show_scops"].value),
            sensor_distance=h["distance"].value,
            height_exaggeration=float(h["exaggeration"].value), auto_exaggeration=bool(h["auto_exaggeration"].value),
            selection=sel,
            sweep=bool(h["sweep"].value),
        )

    # ------------------------------------------------------------ requests
    def request_update(self, *, debounce: bool = True) -> int:
        """Ask for a recomputation with the current controls (the newest request wins).

        ``debounce=False`` (a dropdown, a checkbox, a button: one value per change) starts at once;
        otherwise the worker waits until the controls have been still for ``debounce_s`` (a slider
        drag sends a value per frame).  Returns the request's generation number (see
        :meth:`wait_update`).
        """
        with self._lock:
            self._gen += 1
            gen = self._gen
            now = time.monotonic()
            if self.request_started is None:  # the first request since the app was last idle
                self.request_started = now
            self._last_request = now - (0.0 if debounce else self.debounce_s)
            self._lock.notify_all()
        if not self.background:
            self._run(gen)
        return gen

    def wait_update(self, gen: int, timeout: float = 120.0) -> bool:
        """Block until an update at least as new as ``gen`` ran to completion (pending fits
        shown as pending); False on timeout."""
        end = time.monotonic() + timeout
        with self._lock:
            while self._completed_gen < gen:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._lock.wait(left)
        return True

    def wait_idle(self, timeout: float = 120.0) -> bool:
        """Block until the methods are loaded, every requested update and every queued fit has finished, and an
        open browser has drawn the newest 3D batch (:meth:`_view_drawing`); False on timeout."""
        end = time.monotonic() + timeout
        if not self.methods_ready.wait(timeout):
            return False
        with self._lock:
            while (self._done_gen < self._gen or self._busy
                   or (self.fits is not None and self.fits.busy) or self._view_drawing()):
                now = time.monotonic()
                left = end - now
                if left <= 0:
                    return False
                if self._view_deadline > now:
                    left = min(left, self._view_deadline - now)
                self._lock.wait(left)
        return True

    def _view_drawing(self) -> bool:
        """True while a browser still draws the 3D view it was sent: a browser is open and none has reported the
        newest 3D batch drawn, or one that connected less than :data:`~explorer.app.views.VIEW_DRAWN_WAIT_S` ago
        has not yet reported the state it drew on connecting; never longer than that after the batch was sent or
        the browser connected."""
        now = time.monotonic()
        if now >= self._view_deadline:
            return False
        clients = self._open_browsers()
        if not clients:
            return False
        if self.view_drawn < self._view_sent:
            return True
        ids = [getattr(c, "client_id", None) for c in clients]
        return any(self._views_drawn.get(i, 0) < self._view_sent for i in ids
                   if now - self._client_since.get(i, now) < VIEW_DRAWN_WAIT_S)

    def close(self) -> None:
        """Stop the worker and fit threads (the server is the caller's)."""
        with self._lock:
            self._closing = True
            self._lock.notify_all()
        if self.fits is not None:
            self.fits.close()
        if self._worker is not None:
            self._worker.join(timeout=60)

    def _fit_done(self, key: Hashable, priority: int) -> None:
        """Called by the fit thread (holding the lock) after each fit: redraw with it."""
        if self._closing or key in self._waiting_for:
            return
        now = time.monotonic()
        if priority == 0 or self.fits is None or not self.fits.queued() or now - self._last_trigger > 2.0:
            self._last_trigger = now
            self._gen += 1
            self._lock.notify_all()

    def _work(self) -> None:
        while True:
            with self._lock:
                while self._done_gen >= self._gen and not self._closing:
                    self._lock.wait()
                # debounce: wait until the controls have been still for debounce_s
                while not self._closing:
                    left = self._last_request + self.debounce_s - time.monotonic()
                    if left <= 0:
                        break
                    self._lock.wait(left)
                if self._closing:
                    return
                gen = self._gen
            self._run(gen)

    def _run(self, gen: int) -> None:
        with self._lock:
            self._busy = True
        over = True  # the compilations this update started are over (not so if a newer one takes over)
        try:
            s = self.settings()
            self._expect_compiles(s)
            self.update(s, gen)
            over = not self.pending  # a method still training compiles its kernels in the redraw after
        except Superseded:
            over = False
        except Exception as exc:  # show, never die
            self.errors.append(traceback.format_exc())
            self._status(f"error: {type(exc).__name__}: {exc}", 0.0)
        finally:
            if self.compile_progress is not None and over:
                self.compile_progress.finish()
            with self._lock:
                self._busy = False
                self._done_gen = max(self._done_gen, gen)
                self._lock.notify_all()
            if self.trimmer is not None and not self._closing:
                # an update frees the arrays of the state it replaced (figures, evaluations dropped from the
                # caches); glibc keeps those pages: hand them back once the controls are still (server._Trimmer,
                # TRIM_DELAY_S after the last update), or the resident memory grows ~0.5 MiB per change for good
                self.trimmer()

    # ------------------------------------------------------------ compiling
    def _expect_compiles(self, s: Settings) -> None:
        """Before an update: how many kernels its settings need that numba's cache does not hold (the n of
        "k/n"; :func:`explorer.kernel_cache.uncached`).  Only counted at the start of a burst."""
        progress = self.compile_progress
        if progress is None or progress.started:
            return
        from explorer.kernel_cache import expected_compiles, needed_units

        scene = self.model.fixed_scenes.get(s.preset)
        kind = next((src.kind for src in self.sources if src.label == s.preset), "preset")
        relief = s.relief_m > 0 or (scene is not None and scene.terrain.max_height > scene.terrain.min_height)
        try:
            progress.expected = expected_compiles(needed_units("explore", source=kind, methods=s.methods,
                                                               relief=relief))
        except Exception:  # only the count shown depends on it
            return

    def _show_compiling(self, progress: Any, finished: bool) -> None:
        """Observer of :class:`explorer.kernel_cache.CompileProgress`: the compiling line and its bar."""
        h, gui = self.handles, self.server.gui
        if finished or (progress.current is None and progress.done >= progress.total):
            if "compile_note" in h:
                for key in ("compile_note", "compile_bar"):
                    with contextlib.suppress(Exception):
                        h.pop(key).remove()
                self.compile_log.append("")
            return
        if progress.current is None:
            text = (f"**Compiling kernels for first use** {progress.done}/{progress.total} compiled "
                    f"({progress.seconds:.0f} s so far; `pushbroom warmup` compiles them once ahead)")
        else:
            text = (f"**Compiling kernels for first use** {progress.position}/{progress.total}: "
                    f"`{progress.current}` ({progress.seconds:.0f} s so far; `pushbroom warmup` compiles them "
                    "once ahead)")
        value = 100.0 * progress.done / max(progress.total, 1)
        if "compile_note" not in h:
            order = float(h["status"].order) - 0.5
            h["compile_note"] = gui.add_markdown(text, order=order)
            h["compile_bar"] = gui.add_progress_bar(value, animated=True, order=order + 0.25)
        else:
            h["compile_note"].content = text
            h["compile_bar"].value = value
        self.compile_log.append(text)

    def _check(self, gen: int | None) -> None:
        if gen is not None and (self._gen != gen or self._closing):
            raise Superseded

    def _status(self, text: str, progress: float | None = None, busy: bool = True) -> None:
        self.handles["status"].content = f"**Status:** {text}"
        if progress is not None:
            self.handles["progress"].value = float(np.clip(progress, 0.0, 100.0))
        self.handles["progress"].animated = busy

    def _get_fits(self, jobs: list[tuple[str, int | None]], s: Settings, priority: int,
                  wait_s: float, gen: int | None = None) -> dict[tuple[str, int | None], FitRecord | None]:
        """Fits of (method, density) pairs: inline in foreground mode; in background mode all
        are queued on the fit threads at once (quickest expected first) and waited for at most
        ``wait_s`` together (less if a newer request for ``gen`` arrives); None for those still
        training."""
        m = self.model
        fits = self.fits
        out: dict[tuple[str, int | None], FitRecord | None] = {}
        missing = []
        for name, d in jobs:
            if fits is None or not registry()[name].needs_fit:
                out[(name, d)] = m.fit(name, s, d)
                continue
            out[(name, d)] = m.cached_fit(name, s, d)
            if out[(name, d)] is None:
                key = m.fit_key(name, s, d)
                cost = m.fit_seconds.get(name, 1.0) * (d or s.scop_density) / 100.0
                purpose = SWEEP_PURPOSE if priority > 0 else None  # its log lines name the sweep
                hold = self.hold_long_fits and registry()[name].long_fit
                fits.submit(key, lambda n=name, dd=d, why=purpose: m.fit(n, s, dd, purpose=why),  # type: ignore[misc]
                            priority, cost, hold=hold)
                missing.append((name, d, key))
        if missing and wait_s > 0 and fits is not None:
            keys = [k for _, _, k in missing if k not in fits.held]  # a held fit cannot land meanwhile
            with self._lock:
                self._waiting_for = set(keys)
            try:
                fits.wait_for(keys, time.monotonic() + wait_s,
                                   abort=lambda: gen is not None and (self._gen != gen or self._closing))
            finally:
                with self._lock:
                    self._waiting_for = set()
            for name, d, _ in missing:
                out[(name, d)] = m.cached_fit(name, s, d)
        return out

    def _pending_text(self, name: str, s: Settings) -> str:
        key = self.model.fit_key(name, s)
        started = self.fits.running.get(key) if self.fits is not None else None
        if started is not None:
            return f"training on {s.scop_density} SCOPs ({time.monotonic() - started:.0f} s so far)"
        if self.fits is not None and key in self.fits.held:
            return f"training on {s.scop_density} SCOPs starts once the other maps are drawn"
        return f"queued for training on {s.scop_density} SCOPs"

    def _maps_shown(self, s: Settings) -> None:
        """After an update put its maps on screen: the first time they are complete (methods checked, none shown
        as a preview, none pending but the held trainings), let the long trainings (held until then) start."""
        fits = self.fits
        if not self.hold_long_fits or not s.methods or fits is None:
            return
        if any(r.preview for r in self.runs.values()):  # its full evaluation runs on the fit threads
            return
        if any(self.model.fit_key(n, s) not in fits.held for n in self.pending):
            return
        self.hold_long_fits = False
        self._browsers_caught_up(BROWSER_CATCH_UP_S)
        fits.release()

    def _browsers_caught_up(self, timeout_s: float) -> bool:
        """Block until every open browser has taken in the messages sent so far, and drawn a frame after them.

        A browser applies the server's messages in order, between the frames it draws; the first complete maps
        and their 3D batch are several MB of figure and points for it to parse and draw (in software WebGL on a
        machine without a GPU: seconds of CPU).  Work started on the same CPU before that (the long trainings:
        torch imported, an MLP trained; the accuracy sweep) slowed the first maps on screen.  Each browser is
        asked twice, in turn, for a localStorage value: its first answer comes when it has applied everything
        sent before the question, the second one frame later.  Returns False when ``timeout_s`` passed, a newer
        request arrived or the app closes (then it does not wait longer); True at once without browsers.  Only
        when the held work starts depends on it, never what it computes.
        """
        clients = self._open_browsers()
        if not clients:
            return True
        end = time.monotonic() + timeout_s
        answered = threading.Event()

        def ask() -> None:
            try:
                for _ in range(2):
                    for client in clients:
                        left = end - time.monotonic()
                        if left <= 0:
                            return
                        with contextlib.suppress(Exception):  # a browser that left (or refuses localStorage)
                            client.local_storage.get_item(_CATCH_UP_KEY, timeout=left)
                answered.set()
            finally:
                with self._lock:
                    self._lock.notify_all()

        gen = self._gen
        threading.Thread(target=ask, name="explorer-catch-up", daemon=True).start()
        with self._lock:
            while not answered.is_set() and self._gen == gen and not self._closing:
                left = end - time.monotonic()
                if left <= 0:
                    break
                self._lock.wait(left)
        return answered.is_set()

    def _open_browsers(self) -> list[Any]:
        """The browsers connected now that can answer a localStorage question (viser's ``ClientHandle``)."""
        try:
            clients = list(self.server.get_clients().values())
        except Exception:  # a server double without clients: nothing to wait for
            return []
        return [c for c in clients if hasattr(c, "local_storage")]

