"""The explorer inside a Jupyter notebook: an inline 3D view and interactive residual panels.

Three calls, built from the explorer's own parts:

* :func:`scene_view` -- the explorer's 3D scene of one image, drawn by the SAME viser builders
  (:mod:`explorer.scene3d.builders`: ground footprint, satellite track and sensor frames,
  scanline planes, SCPs coloured by a method's residual, SCOPs, and the ray and search trace of
  a chosen point), serialised with viser's scene serialiser and shown inline through viser's
  static viewer.  The output is a self-contained HTML document in an ``<iframe srcdoc>``, so it
  works in JupyterLab, in VS Code and in a notebook exported to HTML (no server, no kernel).
* :func:`residual_panel` -- the explorer's residual maps
  (:func:`explorer.panels.figures.residual_maps`) as a Plotly ``FigureWidget`` under ipywidgets
  controls (SCOP density on the papers' marks, methods, relief, attitude rate, colour scale).
  Every change recomputes through the model layer the explorer uses
  (:func:`explorer.presets.build_scene`, :func:`explorer.points.simulate_points`,
  :func:`explorer.methods.create`, :func:`explorer.evaluate.evaluate_method`) and updates the
  figure in place.  Displayed, the panel carries a static HTML copy of the current figure as
  well, which is what a notebook exported to HTML shows.
* :func:`interactive_figure` -- any ``make_figure(**values) -> go.Figure`` as a ``FigureWidget``
  redrawn by sliders and dropdowns (``ipywidgets.interact`` abbreviations), with the same static
  copy.

Usage (``pip install -e ".[notebooks]"`` for ipywidgets and anywidget)::

    from explorer.notebook import residual_panel, scene_view
    scene_view("WSU", method="nr")          # inline 3D view with the NR search trace
    panel = residual_panel("WSU", methods=("lrm", "prm"))
    panel                                    # controls + live figure
    panel.controls["scop_density"].value = 30  # the figure follows

This module imports viser, plotly and ipywidgets lazily (only when a view or panel is made).
Conventions: ``docs/conventions.md``; the explorer: ``docs/explorer.md``; the course built on
this module: ``docs/course.md``.
"""

from __future__ import annotations

import contextlib
import html
import io
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.evaluate import Evaluation, evaluate_method
from explorer.methods import BestScanlineMethod, available, create, registry
from explorer.points import PointSet, simulate_points
from explorer.presets import build_scene, preset_ids
from explorer.scene import Scene

SCOP_MARKS = (10, 20, 30, 50, 100, 300, 500, 1000)
"""SCOP counts of the papers' experiments (the density control's stops)."""
COLOUR_LIMITS_PX = (0.01, 0.1, 0.5, 1.0, 2.0, 5.0, 20.0)
"""Colour-scale limits offered, pixels (the ``"fixed"`` scale spans ``[-limit, +limit]``)."""
COLOUR_MODES = ("fixed", "per method", "shared", "log magnitude")
"""Colour scales of the explorer's residual maps (:func:`explorer.panels.figures.residual_maps`)."""


# ============================================================================ 3D view
@dataclass
class SceneView:
    """An inline 3D view: viser's static viewer with one serialised explorer scene.

    Attributes
    ----------
    html : str
        Self-contained HTML document (viser's static client with the scene embedded).
    nodes : list of str
        Scene node names drawn (``/ground/surface``, ``/orbit/track``, ``/scanlines/planes``, ...).
    best_row : float
        Exact best scanline of the chosen point, pixels.
    trace_rows : ndarray, shape (K,) or None
        Rows the chosen method visited, in order (None without a method).
    height : int
        Display height, CSS pixels.
    camera : CameraFraming, optional
        The initial camera (frames the footprint and the track).
    """

    html: str = field(repr=False)
    nodes: list[str]
    best_row: float
    trace_rows: np.ndarray | None = None
    height: int = 480
    camera: CameraFraming | None = None

    def _repr_html_(self) -> str:
        doc = html.escape(self.html, quote=True)
        return (f'<div style="border:1px solid #ddd"><iframe srcdoc="{doc}" width="100%" '
                f'height="{int(self.height)}" style="border:none;display:block"></iframe></div>')

    def save(self, path: str) -> None:
        """Write the standalone HTML document (open it in any browser)."""
        with open(path, "w", encoding="utf-8") as f:
            f.write(self.html)


@dataclass(frozen=True)
class CameraFraming:
    """An initial camera that shows a set of points whole.

    Attributes
    ----------
    position, look_at : ndarray, shape (3,)
        Display coordinates (km).
    fov_rad : float
        Vertical field of view, radians.
    near, far : float
        Clipping distances, km.
    """

    position: np.ndarray
    look_at: np.ndarray
    fov_rad: float
    near: float
    far: float


def frame_points(points_km: np.ndarray, *, view_direction: np.ndarray, fov_rad: float = np.radians(50.0),
                 fill: float = 0.8) -> CameraFraming:
    """The camera looking along ``-view_direction`` at the centre of the points' bounding box, from the distance
    at which the points' perspective image spans ``fill`` of the view's half-height (up = +Z): every point is in
    view, with a margin, for any viewport at least as wide as it is tall.

    Parameters
    ----------
    points_km : ndarray, shape (N, 3)
        What must be seen (display km), e.g. the footprint outline and the track.
    view_direction : ndarray, shape (3,)
        From the target towards the camera (need not be unit length).
    fov_rad : float
        Vertical field of view, radians.
    fill : float
        Largest distance of a projected point from the view centre, as a fraction of the half-height (0, 1).
    """
    p = np.asarray(points_km, dtype=np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if not len(p):
        raise InputError("nothing to frame: no finite point")
    centre = 0.5 * (p.min(axis=0) + p.max(axis=0))
    radius = max(float(np.linalg.norm(p - centre, axis=1).max()), 1e-6)
    if not 0.0 < fill < 1.0:
        raise InputError(f"fill must be in (0, 1), got {fill}")
    v = np.asarray(view_direction, dtype=np.float64)
    v = v / np.linalg.norm(v)
    right = np.cross(-v, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:  # looking straight down: any horizontal "right"
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -v)
    tan_half = np.tan(0.5 * fov_rad)

    def extent(d: float) -> float:  # largest |normalised image coordinate| of the points seen from distance d
        rel = p - (centre + d * v)
        depth = rel @ -v
        if np.any(depth <= 0.0):
            return float("inf")
        return float(np.max(np.abs(np.c_[rel @ right, rel @ up]) / depth[:, None]) / tan_half)

    lo, hi = radius * 1.0001, radius / np.sin(0.5 * fov_rad) / fill  # the sphere fits at hi; in front beyond lo
    for _ in range(60):  # extent decreases with distance: bisect for extent(d) = fill
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if extent(mid) > fill else (lo, mid)
    dist = hi
    return CameraFraming(centre + dist * v, centre, float(fov_rad), max(1e-3, 0.01 * (dist - radius)),
                         2.0 * (dist + radius))


def _view_framing(sc: Scene, frame: Any) -> CameraFraming:
    """Frame the footprint outline and the displayed track, seen from beside the track and above."""
    from explorer.scene3d import builders as B  # noqa: N812

    outline = frame.ground(B.footprint_outline(sc, per_edge=8).reshape(-1, 3))
    _, pos = B.track_positions(sc, 24)
    track = frame.sensor(pos)
    flight = track[-1] - track[0]
    flight[2] = 0.0
    if np.linalg.norm(flight) < 1e-9:
        flight = np.array([0.0, 1.0, 0.0])
    flight /= np.linalg.norm(flight)
    side = np.cross(flight, [0.0, 0.0, 1.0])
    return frame_points(np.vstack([outline, track]), view_direction=side - 0.45 * flight + 0.55 * np.array([0, 0, 1.0]))


def _scene_of(scene: Scene | str) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, str):
        return build_scene(scene)
    raise InputError(f"scene must be a Scene or a preset id ({', '.join(preset_ids())}), got {type(scene).__name__}")


def _ground_of_image_point(scene: Scene, row: float, col: float) -> np.ndarray:
    g = scene.image_to_ground(np.array([row]), np.array([col]))[0]
    if not np.isfinite(g).all():  # off the DEM: the mean-height plane, as the explorer does
        g = scene.image_to_ground(np.array([row]), np.array([col]), height=scene.terrain.mean_height)[0]
    return g


def _method_of(method: str | BestScanlineMethod, scene: Scene, control: PointSet | None, seed: int
               ) -> BestScanlineMethod:
    if isinstance(method, BestScanlineMethod):
        return method
    if method not in available():
        raise InputError(f"unknown method {method!r}; registered: {', '.join(available())}")
    m = create(method, scene)
    if m.needs_fit:
        m.fit(control if control is not None else simulate_points(scene, 100, kind="scop", seed=seed))
    return m


@contextlib.contextmanager
def _quiet():
    """Silence stdout, stderr and rich's console (which in Jupyter displays instead of printing)."""
    import rich

    console = rich.get_console()
    old_file, old_jupyter = getattr(console, "_file", None), console.is_jupyter
    sink = io.StringIO()
    console.file, console.is_jupyter = sink, False
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            yield
    finally:
        console.file = old_file  # type: ignore[assignment]  # as it was (None: rich's default stream)
        console.is_jupyter = old_jupyter


def scene_view(
    scene: Scene | str = "WSU",
    *,
    point: tuple[float, float] | None = None,
    method: str | BestScanlineMethod | None = None,
    check: PointSet | None = None,
    residual_px: np.ndarray | None = None,
    control: PointSet | None = None,
    limit_px: float = 1.0,
    sensor_distance: str = "compressed",
    height_exaggeration: float = 1.0,
    height: int = 480,
    max_points: int = 20000,
    seed: int = 0,
) -> SceneView:
    """The explorer's 3D view of a scene, for inline display in a notebook cell.

    Draws, with :mod:`explorer.scene3d.builders`: the ground footprint (height-coloured with
    relief), the satellite track with sensor frames, the scanline planes of the first, middle and
    last rows and of the chosen point's best row, the chosen point with its ray to the
    perspective centre of its best scanline, and (with ``method``) the scanlines the method
    visited while searching for it.

    Parameters
    ----------
    scene : Scene or str
        A scene or a preset id.
    point : (float, float), optional
        Image (row, column) of the chosen point, pixels; default the image centre.  Its ground
        point is on the terrain (the mean-height plane where a DEM does not cover it).
    method : str or BestScanlineMethod, optional
        Registered method name (fitted on ``control``, or on 100 simulated SCOPs, when it learns)
        or a method instance; its ``ground_to_image(..., trace=True)`` rows are drawn.
    check : PointSet, optional
        SCPs drawn as a point cloud (grey, or coloured by ``residual_px``).
    residual_px : ndarray, shape (len(check),), optional
        Signed row residual per SCP, pixels (NaN: no valid row, drawn magenta).
    control : PointSet, optional
        SCOPs, drawn as gold diamonds.
    limit_px : float
        Colour scale ``[-limit_px, +limit_px]`` of the residuals (the explorer's diverging scale).
    sensor_distance : {"compressed", "true"}
        The explorer's display frame (``docs/explorer.md``).
    height_exaggeration : float
    height : int
        Displayed height, CSS pixels.
    max_points : int
        At most this many SCPs are drawn (an evenly strided subset).
    seed : int
        Seed of the SCOPs simulated for a learned ``method`` when ``control`` is None.

    Returns
    -------
    SceneView
        Displays itself inline (``_repr_html_``); ``.html`` is the standalone document.
    """
    import viser

    from explorer.panels import diverging_rgb
    from explorer.panels.figures import decimation_index
    from explorer.scene3d import builders as B  # noqa: N812

    sc = _scene_of(scene)
    row, col = point if point is not None else ((sc.n_rows - 1) / 2.0, (sc.n_columns - 1) / 2.0)
    row, col = float(row), float(col)
    if not (-0.5 <= row <= sc.n_rows - 0.5 and -0.5 <= col <= sc.n_columns - 0.5):
        raise InputError(f"point (row {row}, col {col}) is outside the image {sc.shape}")
    ground = _ground_of_image_point(sc, row, col)
    trace_rows = None
    if method is not None:
        m = _method_of(method, sc, control, seed)
        res = m.ground_to_image(ground[None, :], trace=True)
        if res.trace:
            trace_rows = np.array([float(np.asarray(a).ravel()[0]) for a in res.trace])
    frame = B.DisplayFrame.for_scene(sc, sensor_distance=sensor_distance, height_exaggeration=height_exaggeration)
    with _quiet():  # viser prints a start-up banner with rich, even with verbose=False
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        api = server.scene
        nodes: dict[str, Any] = {}
        nodes.update(B.add_ground(api, sc, frame))
        nodes.update(B.add_orbit(api, sc, frame))
        h_mean = sc.terrain.mean_height
        rows = np.array([0.0, (sc.n_rows - 1) / 2.0, sc.n_rows - 1.0, row])
        names = ["first scanline (row 0)", "middle scanline", f"last scanline (row {sc.n_rows - 1})", ""]
        nodes.update(B.add_scanline_planes(api, sc, frame, rows, np.array([h_mean, h_mean, h_mean, ground[2]]),
                                           names))
        if check is not None and len(check):
            pos = decimation_index(len(check), max_points)
            if residual_px is not None:
                r = np.asarray(residual_px, dtype=np.float64)
                if r.shape != (len(check),):
                    raise InputError(f"residual_px has shape {r.shape}, expected ({len(check)},) like check")
                colours = diverging_rgb(r[pos], limit_px)
            else:
                colours = np.full((pos.size, 3), 200, np.uint8)
            nodes.update(B.add_points(api, "/points/scps", frame, check.ground[pos], colours,
                                      size_km=B.point_size_km(frame, pos.size)))
        if control is not None and len(control):
            nodes.update(B.add_scops(api, frame, control.ground))
        label = f"row {row:.2f}, col {col:.2f}"
        if trace_rows is not None:
            label += f" ({len(trace_rows)} rows visited)"
        nodes.update(B.add_selection(api, sc, frame, ground, row, trace_rows, label=label))
        cam = _view_framing(sc, frame)
        server.initial_camera.fov = cam.fov_rad
        server.initial_camera.near = cam.near
        server.initial_camera.far = cam.far
        server.initial_camera.up = (0.0, 0.0, 1.0)
        server.initial_camera.look_at = cam.look_at
        server.initial_camera.position = cam.position
        doc = api.as_html()
    finally:
        with _quiet():
            server.stop()
    return SceneView(doc, sorted(nodes), row, trace_rows, int(height), cam)


# ===================================================================== residual panel
@dataclass
class PanelState:
    """What the residual panel's output depends on (one value per control)."""

    preset: str = "WSU"
    methods: tuple[str, ...] = ("lrm", "prm")
    scop_density: int = 100
    relief_m: float = 0.0
    attitude_rate_scale: float = 1.0
    limit_px: float = 1.0
    colour_mode: str = "fixed"


@dataclass
class ResidualPanel:
    """Interactive residual maps: ipywidgets controls over a Plotly ``FigureWidget``.

    Build it with :func:`residual_panel`.  Changing a control (by hand or from Python, e.g.
    ``panel.controls["scop_density"].value = 30``) recomputes the residuals and updates
    :attr:`figure` in place.

    Attributes
    ----------
    controls : dict of str to ipywidgets.Widget
        ``preset``, ``methods``, ``scop_density``, ``relief_m``, ``attitude_rate_scale``, ``limit_px``,
        ``colour_mode``.
    figure : plotly.graph_objects.FigureWidget
        The explorer's residual maps: one scattergl trace per method (``meta`` starts with the
        method name; ``customdata`` holds the signed row residual, pixels, in its first column).
    evaluations : dict of str to Evaluation
        The current residuals per method (``residual_row`` aligned with ``evaluated_index``).
    scene : Scene
    check, control : PointSet
        Current SCPs and SCOPs.
    errors : dict of str to str
        Methods that could not be fitted or evaluated, with the reason.
    """

    n_scps: int
    seed: int
    max_points: int
    controls: dict[str, Any] = field(default_factory=dict)
    figure: Any = None
    status: Any = None
    evaluations: dict[str, Evaluation] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    scene: Scene | None = None
    check: PointSet | None = None
    control: PointSet | None = None
    n_updates: int = 0
    _cache: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------- model layer
    def state(self) -> PanelState:
        """The controls' current values."""
        c = self.controls
        return PanelState(str(c["preset"].value), tuple(c["methods"].value), int(c["scop_density"].value),
                          float(c["relief_m"].value), float(c["attitude_rate_scale"].value),
                          float(c["limit_px"].value), str(c["colour_mode"].value))

    def _cached(self, key: tuple, make):
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = make()
        return self._cache[key]

    def _computed(self) -> tuple[Scene, PointSet, PointSet]:
        """Scene, SCPs and SCOPs of the last :meth:`compute`; :class:`InputError` before the first."""
        if self.scene is None or self.check is None or self.control is None:
            raise InputError("nothing computed yet: call compute() first")
        return self.scene, self.check, self.control

    def compute(self, s: PanelState) -> dict[str, Evaluation]:
        """Scene, SCPs, SCOPs and per-method evaluations for ``s`` (cached by what they depend on)."""
        skey = (s.preset, s.relief_m, s.attitude_rate_scale)
        scene = self._cached(("scene", *skey), lambda: build_scene(
            s.preset, relief_m=s.relief_m, attitude_rate_scale=s.attitude_rate_scale))
        check = self._cached(("scps", *skey, self.n_scps), lambda: simulate_points(
            scene, self.n_scps, kind="scp", seed=self.seed))
        control = self._cached(("scops", *skey, s.scop_density), lambda: simulate_points(
            scene, s.scop_density, kind="scop", seed=self.seed))
        self.scene, self.check, self.control = scene, check, control
        evs: dict[str, Evaluation] = {}
        self.errors = {}
        for name in s.methods:
            def make(name=name) -> Evaluation | str:
                try:
                    return evaluate_method(create(name, scene), check, control, seed=self.seed)
                except Exception as exc:  # shown in the status line; the other methods still draw
                    return f"{type(exc).__name__}: {exc}"
            fitted = registry()[name].needs_fit
            out = self._cached(("eval", *skey, s.scop_density if fitted else None, name), make)
            if isinstance(out, str):
                self.errors[name] = out
            else:
                evs[name] = out
        self.evaluations = evs
        return evs

    def make_figure(self, s: PanelState):
        """The explorer's residual-map figure of the current evaluations (a plain ``go.Figure``)."""
        from explorer.panels.figures import empty_figure, residual_maps

        if not self.evaluations:
            return empty_figure("no method evaluated" + (": " + "; ".join(self.errors.values()) if self.errors else ""))
        fixed = s.colour_mode == "fixed"
        scene, check, control = self._computed()
        fig = residual_maps(self.evaluations, check, control=control, shape=scene.shape,
                            limit_px=s.limit_px if fixed else None, mode=s.colour_mode)
        fig.update_layout(title={"text": f"{scene.name}: relief {s.relief_m:g} m, attitude rate x"
                                         f"{s.attitude_rate_scale:g}, {len(control)} SCOPs",
                                 "font": {"size": 12}, "y": 0.995},
                          margin={"t": 90})
        return fig

    def update(self, *_: Any) -> None:
        """Recompute from the controls and redraw :attr:`figure` in place."""
        s = self.state()
        if self.status is not None:
            self.status.value = "computing..."
        self.compute(s)
        fig = self.make_figure(s)
        with self.figure.batch_update():
            self.figure.data = []
            self.figure.add_traces(list(fig.data))
            self.figure.layout = fig.layout
        self.n_updates += 1
        if self.status is not None:
            parts = [f"{n}: RMSE {ev.rmse_px:.3g} px, dr_max {ev.dr_max_px:.3g} px"
                     for n, ev in self.evaluations.items()]
            parts += [f"<span style='color:#b00'>{n}: {e}</span>" for n, e in self.errors.items()]
            self.status.value = "<br>".join(parts) or "no method selected"

    def scene_view(self, method: str | None = None, **kwargs: Any) -> SceneView:
        """The current scene in 3D: SCPs coloured by ``method``'s residual, SCOPs, and the ray and
        search trace of that method's worst SCP (as the explorer's *worst SCP* selection).

        Parameters
        ----------
        method : str, optional
            One of the evaluated methods; default the first.
        **kwargs
            Passed to :func:`scene_view` (``sensor_distance``, ``height``, ...).
        """
        if not self.evaluations:
            raise InputError("no method evaluated: nothing to colour the points by")
        name = method or next(iter(self.evaluations))
        if name not in self.evaluations:
            raise InputError(f"method {name!r} is not evaluated here; evaluated: {', '.join(self.evaluations)}")
        ev = self.evaluations[name]
        scene, check, control = self._computed()
        residual = np.full(len(check), np.nan)
        residual[np.asarray(ev.evaluated_index)] = ev.residual_row
        worst = int(np.nanargmax(np.abs(residual))) if np.isfinite(residual).any() else len(check) // 2
        fitted = create(name, scene)
        if fitted.needs_fit:
            fitted.fit(control)
        kwargs.setdefault("limit_px", self.state().limit_px)
        return scene_view(scene, point=(float(check.row[worst]), float(check.col[worst])),
                          method=fitted, check=check, residual_px=residual, control=control, **kwargs)

    # --------------------------------------------------------------- display
    @property
    def widget(self):
        """The ipywidgets box: controls, status line, figure."""
        import ipywidgets as W  # noqa: N812

        c = self.controls
        row1 = W.HBox([c["preset"], c["methods"], W.VBox([c["scop_density"], c["colour_mode"], c["limit_px"]])])
        row2 = W.HBox([c["relief_m"], c["attitude_rate_scale"]])
        return W.VBox([row1, row2, self.status, self.figure])

    def static_html(self) -> str:
        """The current figure as an HTML fragment (see :func:`static_figure_html`)."""
        return static_figure_html(self.figure)

    def _repr_mimebundle_(self, **kwargs: Any) -> dict:
        return _widget_bundle(self.widget, self.static_html(), **kwargs)


def residual_panel(
    preset: str = "WSU",
    *,
    methods: Sequence[str] = ("lrm", "prm"),
    scop_density: int = 100,
    relief_m: float = 0.0,
    attitude_rate_scale: float = 1.0,
    limit_px: float = 1.0,
    colour_mode: str = "fixed",
    n_scps: int = 5000,
    seed: int = 0,
    max_points: int = 20000,
    method_choices: Iterable[str] | None = None,
) -> ResidualPanel:
    """Interactive residual maps of best-scanline methods, driven by ipywidgets controls.

    Parameters
    ----------
    preset : str
        Initial preset id.
    methods : sequence of str
        Initially selected methods (registered names).
    scop_density : int
        Initial number of SCOPs; the control offers :data:`SCOP_MARKS` (the papers' counts).
    relief_m : float
        Initial synthetic relief amplitude, metres (control 0 to 2000 m).
    attitude_rate_scale : float
        Initial multiplier of the preset's attitude rates (control 0 to 5).
    limit_px : float
        Initial colour-scale limit of the ``"fixed"`` scale, pixels (control: :data:`COLOUR_LIMITS_PX`).
    colour_mode : str
        Initial colour scale, one of :data:`COLOUR_MODES`: ``"fixed"`` (``[-limit_px, +limit_px]``),
        ``"per method"`` / ``"shared"`` (robust automatic limits), ``"log magnitude"``.
    n_scps : int
        Number of SCPs (check points) the residuals are computed on.
    seed : int
        Seed of the SCOPs, SCPs and subsampling.
    max_points : int
        At most this many SCPs drawn per method.
    method_choices : iterable of str, optional
        Methods offered (default: every registered method).

    Returns
    -------
    ResidualPanel
        Displays as the controls and the live figure; computed once before returning.
    """
    import ipywidgets as W  # noqa: N812
    import plotly.graph_objects as go

    names = available()
    choices = [m for m in (method_choices or names) if m in names]
    unknown = [m for m in methods if m not in names]
    if unknown:
        raise InputError(f"unknown method(s) {', '.join(unknown)}; registered: {', '.join(names)}")
    for m in methods:
        if m not in choices:
            choices.append(m)
    if int(scop_density) not in SCOP_MARKS:
        raise InputError(f"scop_density must be one of the papers' marks {SCOP_MARKS}, got {scop_density}")
    limits = sorted(set(COLOUR_LIMITS_PX) | {float(limit_px)})
    if not limit_px > 0:
        raise InputError(f"limit_px must be positive, got {limit_px}")
    if colour_mode not in COLOUR_MODES:
        raise InputError(f"colour_mode must be one of {COLOUR_MODES}, got {colour_mode!r}")
    if n_scps < 1:
        raise InputError(f"n_scps must be at least 1, got {n_scps}")
    ids = preset_ids()
    match = [p for p in ids if p.lower() == str(preset).lower()]
    if not match:
        raise InputError(f"unknown preset {preset!r}; presets: {', '.join(ids)}")
    style = {"description_width": "initial"}
    controls = {
        "preset": W.Dropdown(options=ids, value=match[0],
                             description="preset", style=style, layout=W.Layout(width="180px")),
        "methods": W.SelectMultiple(options=choices, value=tuple(methods), description="methods", rows=5,
                                    style=style),
        "scop_density": W.SelectionSlider(options=list(SCOP_MARKS), value=int(scop_density),
                                          description="SCOPs", continuous_update=False, style=style),
        "limit_px": W.SelectionSlider(options=limits, value=float(limit_px), description="colour limit (px)",
                                      continuous_update=False, style=style),
        "colour_mode": W.Dropdown(options=list(COLOUR_MODES), value=colour_mode, description="colour scale",
                                  style=style),
        "relief_m": W.FloatSlider(value=float(relief_m), min=0.0, max=2000.0, step=250.0,
                                  description="relief (m)", continuous_update=False, style=style),
        "attitude_rate_scale": W.FloatSlider(value=float(attitude_rate_scale), min=0.0, max=5.0, step=0.5,
                                             description="attitude rate x", continuous_update=False, style=style),
    }
    panel = ResidualPanel(int(n_scps), int(seed), int(max_points), controls)
    panel.status = W.HTML("")
    panel.figure = go.FigureWidget()
    panel.update()
    for c in controls.values():
        c.observe(panel.update, names="value")
    return panel


# ===================================================================== static fallbacks
def static_figure_html(figure: Any) -> str:
    """A Plotly figure as an HTML fragment that draws itself without a kernel and without the network.

    Draws with the page's plotly.js: ``window.Plotly`` (a page of ``notebooks/build_course.py`` embeds it
    once in its head), or the ``plotly`` module that plotly's ``notebook`` renderer registers with require.js.
    Nothing is fetched: without a plotly.js on the page the fragment says so in place of the figure.
    """
    import json
    import uuid

    import plotly.graph_objects as go
    import plotly.io as pio

    fig = go.Figure(figure)
    div = f"pbx-{uuid.uuid4().hex}"
    spec = pio.to_json(fig, validate=False).replace("</", "<\\/")
    height = fig.layout.height or 450
    missing = ("<p style='color:#b00'>This figure needs plotly.js on the page (an exported course page has it; "
               "in a live notebook the widget above draws it).</p>")
    return (
        f'<div id="{div}" class="pbx-figure" style="height:{int(height)}px;width:100%"></div>'
        '<script type="text/javascript">'
        f"(function(){{var s={spec};var draw=function(P){{P.newPlot({json.dumps(div)},s.data,s.layout,"
        "{responsive:true});};"
        "if(window.Plotly){draw(window.Plotly);}"
        "else if(window.requirejs&&requirejs.defined&&requirejs.defined('plotly')){require(['plotly'],draw);}"
        f"else{{document.getElementById({json.dumps(div)}).innerHTML={json.dumps(missing)};}}"
        "})();</script>"
    )


def _widget_bundle(widget: Any, static_html: str, **kwargs: Any) -> dict:
    """A widget's display bundle with a static ``text/html`` copy for kernel-less viewers."""
    bundle = widget._repr_mimebundle_(**kwargs) or {}
    data = dict(bundle[0] if isinstance(bundle, tuple) else bundle)
    data["text/html"] = static_html
    return data


@dataclass
class InteractiveFigure:
    """A Plotly ``FigureWidget`` redrawn by a function of ipywidgets controls.

    Build it with :func:`interactive_figure`; ``controls[name].value = v`` redraws.

    Attributes
    ----------
    controls : dict of str to ipywidgets.Widget
    figure : plotly.graph_objects.FigureWidget
    make_figure : callable
        ``make_figure(**values) -> go.Figure``.
    n_updates : int
    """

    make_figure: Any
    controls: dict[str, Any]
    figure: Any
    n_updates: int = 0

    def values(self) -> dict[str, Any]:
        """The controls' current values."""
        return {k: c.value for k, c in self.controls.items()}

    def update(self, *_: Any) -> None:
        """Call ``make_figure`` with the controls' values and redraw :attr:`figure` in place."""
        fig = self.make_figure(**self.values())
        with self.figure.batch_update():
            self.figure.data = []
            self.figure.add_traces(list(fig.data))
            self.figure.layout = fig.layout
        self.n_updates += 1

    @property
    def widget(self):
        """The ipywidgets box: controls above the figure."""
        import ipywidgets as W  # noqa: N812

        return W.VBox([W.HBox(list(self.controls.values())), self.figure])

    def _repr_mimebundle_(self, **kwargs: Any) -> dict:
        return _widget_bundle(self.widget, static_figure_html(self.figure), **kwargs)


def interactive_figure(make_figure: Any, **controls: Any) -> InteractiveFigure:
    """A figure that follows sliders: ``make_figure(**values)`` redrawn whenever a control changes.

    Parameters
    ----------
    make_figure : callable(**values) -> plotly.graph_objects.Figure
    **controls
        One control per keyword argument of ``make_figure``, written as for
        ``ipywidgets.interact``: ``(min, max, step)`` for a slider (float if any bound is a
        float), a list or tuple of values for a dropdown, a bool for a checkbox, or an
        ipywidgets widget.  The control starts at the slider's middle / the first value, or at
        ``make_figure``'s default for that argument when it has one inside the range.

    Returns
    -------
    InteractiveFigure
        Displays as the controls over the live figure (a static copy for exported notebooks).
    """
    import inspect

    import ipywidgets as W  # noqa: N812
    import plotly.graph_objects as go

    if not controls:
        raise InputError("interactive_figure needs at least one control")
    defaults = {k: p.default for k, p in inspect.signature(make_figure).parameters.items()
                if p.default is not inspect.Parameter.empty}
    widgets = {}
    for name, abbrev in controls.items():
        if isinstance(abbrev, W.Widget):
            w = abbrev
        else:
            w = (W.interactive.widget_from_abbrev(abbrev, defaults[name]) if name in defaults
                 else W.interactive.widget_from_abbrev(abbrev))
            if w is None:
                raise InputError(f"control {name!r}: cannot make a widget from {abbrev!r}")
            if hasattr(w, "continuous_update"):
                w.continuous_update = False
        w.description = name
        w.style = {"description_width": "initial"}
        widgets[name] = w
    out = InteractiveFigure(make_figure, widgets, go.FigureWidget())
    out.update()
    for w in widgets.values():
        w.observe(out.update, names="value")
    return out


__all__ = ["COLOUR_LIMITS_PX", "COLOUR_MODES", "SCOP_MARKS", "CameraFraming", "InteractiveFigure", "PanelState",
           "ResidualPanel", "SceneView", "frame_points", "interactive_figure", "residual_panel", "scene_view",
           "static_figure_html"]
