"""The explorer's controls in the viser panel, and the bridge that turns a click on a residual map
into a selected point in the 3D view.

:class:`Controls` adds every control and owns the handles (``controls.handles``, ``{key: handle}``);
its callbacks only *request* work from their host -- any object with the public methods of
:class:`ControlsHost` (the :class:`~explorer.app.gui.ExplorerApp`; this module never imports it), whose
worker thread debounces and computes.  Control -> cache table: ``docs/explorer.md#controls``.

Map clicks: viser draws Plotly figures in the browser but reports no Plotly events, so a small
script (run once per page by an HTML element's ``onerror`` handler, the only way viser's HTML
element runs code) listens for ``plotly_click`` on every Plotly plot and types the clicked
point's SCP index (the second ``customdata`` column of the maps) into the *Picked SCP* text
control, as a user would; its callback selects that SCP.  Nothing is loaded from the network.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from typing import Any, Protocol

import numpy as np

from explorer.app.model import COLOUR_LIMITS_PX, COLOUR_MODES, COMPONENTS, SCOP_DENSITIES, SCP_COUNTS
from explorer.panels.raster import AGGREGATES

NO_DIFFERENCE = "(none)"
SLIDERS = ("relief", "rates", "jitter", "layers", "neurons", "exaggeration")
"""Controls dragged through many values (their updates are debounced)."""
"""Difference-map dropdown entry: no difference map."""

CLICK_SCRIPT = r"""
(function () {
  if (window.__pushbroomPick) { window.__pushbroomPick.uuid = '%(uuid)s'; return; }
  const state = {uuid: '%(uuid)s'};
  window.__pushbroomPick = state;
  function pickInput() {
    const label = document.querySelector('label[for="' + state.uuid + '"]');
    let node = label;
    while (node && !(node.querySelector && node.querySelector('input'))) node = node.parentElement;
    return node ? node.querySelector('input') : null;
  }
  function type(text) {
    const input = pickInput();
    if (!input) return;
    const setter = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, 'value').set;
    setter.call(input, text);
    input.dispatchEvent(new Event('input', {bubbles: true}));
  }
  function attach() {
    for (const gd of document.querySelectorAll('.js-plotly-plot')) {
      if (gd.__pushbroomPick || typeof gd.on !== 'function') continue;
      gd.__pushbroomPick = true;
      gd.on('plotly_click', function (ev) {
        const p = ev && ev.points && ev.points[0];
        if (!p || !p.customdata || !(p.customdata.length >= 2)) return;  /* may be a typed array */
        type('scp ' + Math.round(p.customdata[1]));
      });
    }
  }
  state.attach = attach;
  setInterval(attach, 500);
  /* a click on a plot attaches first (timers of a page in the background may be throttled) */
  document.addEventListener('pointerdown', attach, true);
  document.addEventListener('mousedown', attach, true);
})();
"""


DRAWN_SCRIPT = r"""
(function () {
  if (window.__pushbroomDrawn) { window.__pushbroomDrawn.uuid = '%(uuid)s'; return; }
  const state = {uuid: '%(uuid)s', sent: null};
  window.__pushbroomDrawn = state;
  function row() {
    const label = document.querySelector('label[for="' + state.uuid + '"]');
    let node = label;
    while (node && !(node.querySelector && node.querySelector('input'))) node = node.parentElement;
    return node;
  }
  function report(gd) {
    const meta = gd.layout && gd.layout.meta;
    const rev = meta && meta.revision;
    if (rev === undefined || rev === null || rev === state.sent) return;
    const node = row();
    const input = node ? node.querySelector('input') : null;
    if (!input) return;
    state.sent = rev;
    /* after the next frame has painted them (a rAF callback runs before that frame's paint, a task after it) */
    requestAnimationFrame(function () {
      setTimeout(function () {
        const setter = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, 'value').set;
        setter.call(input, 'drawn ' + rev);
        input.dispatchEvent(new Event('input', {bubbles: true}));
      }, 0);
    });
  }
  function attach() {
    const node = row();
    if (node && node.style.display !== 'none') node.style.display = 'none';
    for (const gd of document.querySelectorAll('.js-plotly-plot')) {
      if (typeof gd.on !== 'function') continue;
      if (!gd.__pushbroomDrawn) {
        gd.__pushbroomDrawn = true;
        gd.on('plotly_afterplot', function () { report(gd); });
      }
      report(gd);  /* drawn before the listener was attached, or the control was not in the page yet */
    }
  }
  setInterval(attach, 250);
})();
"""
"""Tells the server which maps the page has drawn: after each Plotly drawing of a figure whose ``layout.meta`` has a
``revision``, once the next frame has painted it, types ``drawn <revision>`` into the (hidden) text control ``uuid``
(the handle ``maps_drawn``)."""


VIEW_DRAWN_SCRIPT = r"""
(function () {
  if (window.__pushbroomView) { window.__pushbroomView.uuid = '%(uuid)s'; return; }
  const state = {uuid: '%(uuid)s', draws: 0, lastDraw: 0, target: 0, since: 0, drawsAtStart: 0, watching: false,
                 reports: 0,
                 page: Math.random().toString(36).slice(2, 10)};
  window.__pushbroomView = state;
  function counted(orig) {
    return function () {
      const c = this.canvas;
      if (!(c && c.closest && c.closest('.js-plotly-plot'))) { state.draws++; state.lastDraw = performance.now(); }
      return orig.apply(this, arguments);
    };
  }
  for (const C of [window.WebGLRenderingContext, window.WebGL2RenderingContext]) {
    if (!C) continue;
    for (const f of ['drawArrays', 'drawElements', 'drawArraysInstanced', 'drawElementsInstanced']) {
      if (typeof C.prototype[f] === 'function') C.prototype[f] = counted(C.prototype[f]);
    }
  }
  function input() {
    const label = document.querySelector('label[for="' + state.uuid + '"]');
    let node = label;
    while (node && !(node.querySelector && node.querySelector('input'))) node = node.parentElement;
    if (node && node.style.display !== 'none') node.style.display = 'none';
    return node ? node.querySelector('input') : null;
  }
  /* a newer batch than the one watched: watch it instead (its frames count from now).  A page that opens finds
     "view <n>", or "drawn <n>" when another page has reported it: it draws that state too */
  function take(inp) {
    const m = inp ? /^(view|drawn) (\d+)( |$)/.exec(inp.value) : null;
    if (!m || Number(m[2]) <= state.target) return false;
    state.target = Number(m[2]);
    state.since = performance.now();
    state.drawsAtStart = state.draws;
    return true;
  }
  function report(inp) {
    const setter = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, 'value').set;
    state.reports++;  /* a text of its own each time: viser passes on only a changed value */
    setter.call(inp, 'drawn ' + state.target + ' ' + state.page + '.' + state.reports);
    inp.dispatchEvent(new Event('input', {bubbles: true}));
    state.watching = false;
  }
  function watch() {
    function tick() {
      take(input());
      const now = performance.now();
      const drew = state.draws > state.drawsAtStart;
      const quiet = now - Math.max(state.lastDraw, state.since) >= %(quiet_ms)d;
      if ((quiet && (drew || now - state.since > %(no_draw_ms)d)) || now - state.since > %(max_ms)d) {
        setTimeout(function () {
          const inp = input();
          if (!inp) { state.watching = false; return; }
          if (take(inp)) { requestAnimationFrame(tick); return; }  /* arrived meanwhile: not drawn yet */
          report(inp);
        }, 0);
        return;
      }
      requestAnimationFrame(tick);
    }
    requestAnimationFrame(tick);
  }
  setInterval(function () {
    const inp = input();
    if (document.hidden) {  /* a hidden page draws nothing (no animation frames): nothing to wait for */
      if ((take(inp) || state.watching) && inp) report(inp);
      return;
    }
    if (!state.watching && take(inp)) {
      state.watching = true;
      watch();
    }
  }, 40);
})();
"""
"""Tells the server when the page's 3D view has drawn what it was sent.

The server ends an update's 3D batch by typing ``view <revision>`` into the (hidden) text control ``uuid`` (the
handle ``view_drawn``).  Once the page has applied it, the script waits until the 3D view's WebGL canvas has drawn
at least once (or ``no_draw_ms`` passed: the batch changed nothing drawn) and then made no draw call for
``quiet_ms`` -- viser renders on demand but keeps drawing for 250 ms after each request, and a software frame read
back to the CPU lasts up to ~250 ms, so a shorter gap lies between two frames of one burst -- and types
``drawn <revision> <page>.<k>`` back, at the latest ``max_ms`` after it saw the revision (the page's token and report
count make each report a new value, which viser passes on).  A page that opens draws the state it finds
(``view <n>``, or ``drawn <n> ...`` from another page) and reports it too; a hidden page (no animation frames)
reports at once.  Draw calls are counted by wrapping the WebGL contexts' draw functions; Plotly's own WebGL
canvases (inside ``.js-plotly-plot``) are not counted."""


VIEW_QUIET_MS = 350
"""The page's 3D view counts as drawn once its canvas has made no draw call for this long (longer than the gap
between two frames of one of viser's render bursts, a software frame's read-back included)."""
VIEW_NO_DRAW_MS = 300
"""A 3D batch after which the page's 3D view drew nothing for this long counts as drawn (it changed nothing shown)."""
VIEW_MAX_MS = 5000
"""The page reports a 3D batch drawn at the latest this long after it saw it."""


PLOTLY_SIZE_SCRIPT = r"""
(function () {
  if (window.__pushbroomPlotlySize) return;
  window.__pushbroomPlotlySize = true;
  function wrap(P) {
    if (!P || typeof P.react !== 'function' || P.react.__pushbroomSized) return P;
    const react = P.react;
    function same(a, b) {
      const ka = Object.keys(a), kb = Object.keys(b);
      return ka.length === kb.length && ka.every(function (k) { return a[k] === b[k]; });
    }
    const sized = function (gd, data, layout, config) {
      const last = gd && gd.__pushbroomSized;
      if (gd) gd.__pushbroomSized = null;
      /* the component's second call, once measured: the figure already drawn at that size */
      if (last && last.data === data && last.config === config && layout && same(last.layout, layout)) {
        return Promise.resolve(gd);
      }
      const hw = layout && layout.meta && layout.meta.height_over_width;
      const box = gd && gd.parentElement;
      if (layout && layout.width === 0 && typeof hw === 'number' && hw > 0 && box) {
        const w = box.getBoundingClientRect().width;
        if (w > 0) {
          layout = Object.assign({}, layout, {width: w, height: w * hw});
          gd.__pushbroomSized = {data: data, layout: layout, config: config};
        }
      }
      return react.call(this, gd, data, layout, config);
    };
    sized.__pushbroomSized = true;
    P.react = sized;
    return P;
  }
  if (window.Plotly) { wrap(window.Plotly); return; }
  const before = Object.getOwnPropertyDescriptor(window, 'Plotly');  /* another hook's: kept, fed the wrapped one */
  let plotly;
  Object.defineProperty(window, 'Plotly', {configurable: true, enumerable: true,
    get: before && before.get ? before.get : function () { return plotly; },
    set: before && before.set ? function (v) { before.set.call(window, wrap(v)); }
                              : function (v) { plotly = wrap(v); }});
})();
"""
"""Draws a figure viser's Plotly component mounts before it measured its box at the box's size at once.

The component first calls ``Plotly.react`` with ``width`` 0 (its size not yet measured) and again once its
``ResizeObserver`` reported the box: a 1.4 MB maps figure was drawn twice, the second time (0.15-0.35 s in software,
after the 3D view's first frame) inside the first SCOP change after loading.  For a figure whose ``layout.meta`` has
``height_over_width`` (the explorer's figures; the handle's ``aspect`` is set from it), a call with width 0 uses the
box's width (the component's ``Paper``: the plot's parent element, what the observer reports) and that height; the
component's second call then asks for the same figure (the same ``data`` and ``config`` objects, every layout entry
the same) at that size and is answered without a redraw (Plotly's own ``react`` re-decodes the base64 arrays and
redraws the whole figure even then: 0.3 s).  Runs before plotly.min.js
(a setter on ``window.Plotly``) or wraps it when already loaded."""


def _script_html(script: str) -> str:
    """HTML whose ``onerror`` runs ``script`` once the element is in the page."""
    script = script.replace("\n", " ").replace('"', "&quot;")
    return f'<img src="data:," alt="" style="display:none" onerror="{script}">'


def click_bridge_html(uuid: str) -> str:
    """HTML whose ``onerror`` runs :data:`CLICK_SCRIPT` for the text control ``uuid``."""
    return _script_html(CLICK_SCRIPT % {"uuid": uuid})


def view_drawn_bridge_html(uuid: str) -> str:
    """HTML whose ``onerror`` runs :data:`VIEW_DRAWN_SCRIPT` for the text control ``uuid``."""
    return _script_html(VIEW_DRAWN_SCRIPT % {"uuid": uuid, "quiet_ms": VIEW_QUIET_MS, "no_draw_ms": VIEW_NO_DRAW_MS,
                                             "max_ms": VIEW_MAX_MS})


def drawn_bridge_html(uuid: str) -> str:
    """HTML whose ``onerror`` runs :data:`DRAWN_SCRIPT` for the text control ``uuid``."""
    return _script_html(DRAWN_SCRIPT % {"uuid": uuid})


class ControlsHost(Protocol):
    """What the controls need from the app: its public methods only."""

    def request_update(self, *, debounce: bool = True) -> int: ...

    def reset_view(self) -> None: ...

    def export_to_client(self, client: Any = None) -> None: ...

    def quiet(self) -> AbstractContextManager[None]: ...

    def is_quiet(self) -> bool: ...


def color_options(methods: Sequence[str]) -> tuple[str, ...]:
    """Entries of the colour-by dropdown for the checked ``methods``."""
    return tuple(methods) if methods else ("(none)",)


class Controls:
    """The explorer's controls and panels in ``gui`` (a viser GUI API); owns their handles.

    Parameters
    ----------
    host : ControlsHost
        Receives the requests (update, reset view, export); programmatic changes made inside
        ``host.quiet()`` trigger nothing.
    gui : viser GuiApi
    scene_ids : list of str
        Entries of the scene dropdown (the loaded sources' labels, then the presets).
    scene_id : str
        The entry shown first.
    scp_count, scop_density : int
    sweep : bool
    """

    def __init__(self, host: ControlsHost, gui: Any, *, scene_ids: list[str], scene_id: str, scp_count: int,
                 scop_density: int, sweep: bool) -> None:
        from explorer.panels import figures as F  # noqa: N812  (plotly: imported with the GUI only)

        self.host = host
        self.gui = gui
        gui.configure_theme(control_width="medium", show_share_button=False)
        with contextlib.suppress(Exception):
            gui.main_panel.dock_left()
        h: dict[str, Any] = {}
        self.handles = h
        h["status"] = gui.add_markdown("**Status:** starting")
        h["progress"] = gui.add_progress_bar(0.0, animated=False)
        h["run"] = gui.add_button("Run", hint="recompute now (also after changes with auto update off)")
        h["auto"] = gui.add_checkbox("Update on change", True)
        with gui.add_folder("Scene"):
            h["preset"] = gui.add_dropdown("Scene", scene_ids, initial_value=scene_id,
                                           hint="a loaded file (named by file and sensor) or a synthetic preset")
            h["relief"] = gui.add_slider("Relief (m)", 0, 3000, 100, 0, hint="presets only")
            h["rates"] = gui.add_slider("Attitude rate scale", 0.0, 5.0, 0.1, 1.0, hint="presets only")
            h["jitter"] = gui.add_slider("Jitter amplitude scale", 0.0, 10.0, 0.5, 1.0, hint="presets only")
        with gui.add_folder("Points"):
            densities = sorted(set(SCOP_DENSITIES) | {int(scop_density)})
            h["density"] = gui.add_dropdown("SCOPs", [str(d) for d in densities],
                                            initial_value=str(int(scop_density)))
            counts = sorted(set(SCP_COUNTS) | {int(scp_count)})
            h["scps"] = gui.add_dropdown("SCPs (maps)", [str(c) for c in counts], initial_value=str(int(scp_count)))
        with gui.add_folder("Methods") as folder:
            self.methods_folder = folder
            h["method_boxes"] = {}
            h["methods_note"] = gui.add_markdown("*Loading the methods...*")
            h["color_method"] = gui.add_dropdown("Colour by", color_options([]))
            h["layers"] = gui.add_slider("MLP layers", 1, 5, 1, 1, hint="hidden layers, for methods that take them")
            h["neurons"] = gui.add_slider("MLP neurons", 2, 50, 1, 10,
                                          hint="neurons per hidden layer, for methods that take them")
            h["sweep"] = gui.add_checkbox("Accuracy vs SCOPs sweep", sweep)
        with gui.add_folder("Residual maps"):
            h["colour_mode"] = gui.add_dropdown(
                "Colour scale", COLOUR_MODES, initial_value=COLOUR_MODES[0],
                hint="per method / shared: symmetric limit from the 99th percentile of |residual| (named on the "
                     "colour bar); log magnitude: log10 |residual|; fixed: the limit below")
            h["limit"] = gui.add_dropdown("Fixed limit +- px", [f"{v:g}" for v in COLOUR_LIMITS_PX], initial_value="1")
            h["component"] = gui.add_dropdown("Residual", COMPONENTS, initial_value=COMPONENTS[0],
                                              hint="row (scanline) residual, column residual, or both")
            h["aggregate"] = gui.add_dropdown("Cell value", AGGREGATES, initial_value=AGGREGATES[0],
                                              hint="each map cell: the signed mean of its check points' residuals, "
                                                   "or the (signed) residual of largest magnitude among them")
            h["diff_a"] = gui.add_dropdown("Difference: A", (NO_DIFFERENCE,), hint="map of A minus B (row residual)")
            h["diff_b"] = gui.add_dropdown("Difference: B", (NO_DIFFERENCE,))
            h["show_scops"] = gui.add_checkbox("SCOP overlay on maps", True)
            h["export"] = gui.add_button("Export (summary, residuals, panels)",
                                         hint="every check point, no subsample: a zip of summary.json, "
                                              "residuals.csv and panels.html (as `pushbroom explore --export`)")
        with gui.add_folder("View"):
            h["distance"] = gui.add_dropdown("Sensor distance", ("compressed", "true"))
            h["auto_exaggeration"] = gui.add_checkbox(
                "Automatic height exaggeration", True,
                hint="exaggerate heights so the terrain's relief shows (the factor is stated under the maps' 3D "
                     "text); moving the slider sets it by hand")
            h["exaggeration"] = gui.add_slider("Height exaggeration", 1.0, 50.0, 0.5, 1.0)
            h["reset_view"] = gui.add_button("Reset view", hint="frame the footprint and the track again")
        with gui.add_folder("Selected point"):
            h["sel_mode"] = gui.add_dropdown("Select", ("worst SCP", "image point", "picked SCP"))
            h["sel_row"] = gui.add_slider("Row", 0.0, 1e6, 0.5, 0.0)
            h["sel_col"] = gui.add_slider("Column", 0.0, 1e6, 0.5, 0.0)
            h["pick"] = gui.add_text("Picked SCP", "", hint="click a cell of a residual map (or type `scp <index>`)")
            h["sel_text"] = gui.add_markdown("")
        h["click_bridge"] = gui.add_html(click_bridge_html(h["pick"]._impl.uuid))
        h["cloud_text"] = gui.add_markdown("")
        # the page reports here which maps it has drawn (its row hidden by the script): the 3D view's part of an
        # update waits for it (explorer.app.views.Views.update)
        h["maps_drawn"] = gui.add_text("Maps drawn", "", hint="set by the page: the revision of the maps it drew")
        h["drawn_bridge"] = gui.add_html(drawn_bridge_html(h["maps_drawn"]._impl.uuid))
        # and when its 3D view has drawn an update's 3D batch: the update ends then (Views._wait_view_drawn)
        h["view_drawn"] = gui.add_text("View drawn", "", hint="set by the page: the 3D batch it drew")
        h["view_bridge"] = gui.add_html(view_drawn_bridge_html(h["view_drawn"]._impl.uuid))

        self.panel = gui.add_panel()
        config = F.PLOTLY_CONFIG
        with contextlib.suppress(Exception):  # viser's own message; before the first figure (and plotly.min.js)
            from viser._messages import RunJavascriptMessage

            gui._websock_interface.queue_message(RunJavascriptMessage(source=PLOTLY_SIZE_SCRIPT))
        with self.panel.add_tab("Residual maps"):
            h["maps"] = gui.add_plotly(F.empty_figure("computing..."), aspect=0.5, config=config)
            h["maps_note"] = gui.add_markdown("")
            h["summary"] = gui.add_markdown("")
        with self.panel.add_tab("Accuracy vs SCOPs"):
            h["accuracy"] = gui.add_plotly(F.empty_figure("computing..."), aspect=0.5, config=config)
        with self.panel.add_tab("Timing"):
            h["timing"] = gui.add_plotly(F.empty_figure("computing..."), aspect=0.5, config=config)
        with contextlib.suppress(Exception):
            self.panel.dock_right()
            self.panel.set_width(560)

        for key in ("preset", "density", "scps", "color_method", "limit", "colour_mode", "component", "aggregate",
                    "diff_a", "diff_b", "show_scops", "distance", "sweep", "sel_mode", "auto_exaggeration"):
            h[key].on_update(self.changed)  # one value per change: computed at once
        for key in SLIDERS:
            h[key].on_update(self._exaggeration_slid if key == "exaggeration" else self.slid)  # debounced
        h["sel_row"].on_update(self._selection_changed)
        h["sel_col"].on_update(self._selection_changed)
        h["pick"].on_update(self._picked)
        h["run"].on_click(lambda _e: host.request_update(debounce=False))
        h["reset_view"].on_click(lambda _e: host.reset_view())
        h["export"].on_click(lambda e: host.export_to_client(getattr(e, "client", None)))

    # ------------------------------------------------------------- callbacks
    def changed(self, _event: Any = None, *, debounce: bool = False) -> None:
        """A control changed: request an update (unless quiet or auto update is off)."""
        if self.host.is_quiet():
            return
        if self.handles["auto"].value:
            self.host.request_update(debounce=debounce)

    def slid(self, _event: Any = None) -> None:
        """A slider moved: request a debounced update."""
        self.changed(debounce=True)

    def _exaggeration_slid(self, _event: Any = None) -> None:
        """The height exaggeration set by hand: the automatic one is off."""
        if not self.host.is_quiet():
            with self.host.quiet():
                self.handles["auto_exaggeration"].value = False
        self.slid()

    def _selection_changed(self, _event: Any = None) -> None:
        if self.host.is_quiet():
            return
        with self.host.quiet():
            self.handles["sel_mode"].value = "image point"
        self.changed(debounce=True)

    def _picked(self, _event: Any = None) -> None:
        if self.host.is_quiet():
            return
        if self.pick_index() is not None:
            with self.host.quiet():
                self.handles["sel_mode"].value = "picked SCP"
            self.host.request_update(debounce=False)

    def _methods_changed(self, _event: Any = None) -> None:
        if self.host.is_quiet():
            return
        with self.host.quiet():
            self.set_method_options(self.checked_methods())
        self.changed()

    # ---------------------------------------------------------------- methods
    def add_method_boxes(self, names: Sequence[str], checked: Sequence[str], hints: Callable[[str], str]) -> None:
        """One checkbox per method (``checked`` ticked), after the methods note."""
        h = self.handles
        base = float(h["methods_note"].order)
        with self.methods_folder:
            for k, name in enumerate(names):
                box = self.gui.add_checkbox(name, name in checked, order=base + (k + 1) / (len(names) + 1),
                                            hint=hints(name)[:300])
                box.on_update(self._methods_changed)
                h["method_boxes"][name] = box

    def mark_unavailable(self, reasons: dict[str, str | None]) -> None:
        """Label the method checkboxes the current sensor cannot serve ``"name (unavailable here)"`` with the reason
        as their hint (a search method on an RPC); the others get their name and first hint back."""
        hints = self.__dict__.setdefault("_method_hints", {})
        for name, box in self.handles["method_boxes"].items():
            hints.setdefault(name, box.hint)
            reason = reasons.get(name)
            label, hint = (name, hints[name]) if reason is None else (f"{name} (unavailable here)", reason[:300])
            if box.label != label:
                box.label, box.hint = label, hint

    def checked_methods(self) -> list[str]:
        return [n for n, b in self.handles["method_boxes"].items() if b.value]

    def set_method_options(self, methods: Sequence[str]) -> None:
        """Offer the checked methods in the colour-by and difference dropdowns."""
        h = self.handles
        h["color_method"].options = color_options(methods)
        opts = (NO_DIFFERENCE, *methods)
        for key in ("diff_a", "diff_b"):
            if h[key].value not in opts:
                h[key].value = NO_DIFFERENCE
            h[key].options = opts

    def set_mlp_defaults(self, layers: int, neurons: int) -> None:
        self.handles["layers"].value = int(np.clip(layers, 1, 5))
        self.handles["neurons"].value = int(np.clip(neurons, 2, 50))

    def pick_index(self) -> int | None:
        """The SCP index typed into (or clicked into) the *Picked SCP* control, if any."""
        m = re.fullmatch(r"\s*(?:scp\s*)?(\d+)\s*", str(self.handles["pick"].value))
        return int(m.group(1)) if m else None


__all__ = ["CLICK_SCRIPT", "DRAWN_SCRIPT", "NO_DIFFERENCE", "PLOTLY_SIZE_SCRIPT", "VIEW_DRAWN_SCRIPT", "VIEW_MAX_MS",
           "VIEW_NO_DRAW_MS", "VIEW_QUIET_MS", "Controls", "ControlsHost", "click_bridge_html", "color_options",
           "drawn_bridge_html", "view_drawn_bridge_html"]
