"""The explorer's model: scenes, points, fits and evaluations with caches; no viser, no plotly.

:class:`ExplorerModel` builds scenes (a preset with the GUI's relief / attitude / jitter
controls, or a fixed scene loaded from a file by :mod:`explorer.sources`), SCOPs and SCPs,
fits and evaluates methods through ``explorer.methods.create`` /
``explorer.evaluate.evaluate_method``, and caches every result by what it depends on --
scenes by (scene id, relief, attitude rates, jitter), SCOPs by (scene, density), SCPs by
(scene, count), fits by (scene, SCOPs, method, params), evaluations by (fit, SCPs,
subsample).  Every number the explorer shows comes from **every** SCP, whatever the load of the
machine: the only subsample is a *preview* -- a fixed, seeded set of ``preview_points`` SCPs --
shown first for a method whose full evaluation is projected to take longer than
``preview_after_s``, while the full one computes; the GUI names it as a preview and replaces it
by the full result (:meth:`ExplorerModel.needs_preview`).  Only *when* the full result appears
depends on the machine, never what it is.

Every evaluated point carries a status (:data:`STATUS_NAMES`): valid, *refused* (the method
declined to answer outside its domain, e.g. a regression's height extrapolation), not
converged, outside the image, or outside the sensor's tables (a CSM camera whose tables stop
mid-image).  Usage and the GUI: ``docs/explorer.md``; conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from explorer import _log
from explorer.evaluate import Evaluation, evaluate_method
from explorer.methods import available, create, registry, unavailable_reason
from explorer.methods.base import BestScanlineMethod
from explorer.panels import count_text
from explorer.points import PointSet, simulate_points
from explorer.presets import build_scene
from explorer.scene import Scene

SCOP_DENSITIES = (10, 20, 30, 50, 100, 300, 500, 1000)
"""SCOP counts offered (the papers' marks)."""
SCP_COUNTS = (1_000, 10_000, 50_000, 100_000, 250_000)
COLOUR_LIMITS_PX = (0.01, 0.1, 0.5, 1.0, 2.0, 5.0, 20.0)
"""Fixed colour limits offered besides the automatic modes."""
COLOUR_MODES = ("per method", "shared", "log magnitude", "fixed")
"""Residual-map colour scales: a robust symmetric limit per map (default) or one for all maps
(both from residual percentiles, :func:`explorer.panels.robust_limit`), log10 of |residual|,
or the fixed ``Settings.limit_px``."""
COMPONENTS = ("row", "column", "row and column")
"""Which residual the maps show: the scanline (row) residual, the column residual, or both."""
STATUS_NAMES = ("valid", "refused", "not converged", "outside image", "outside tables")
"""Per-point status codes of :attr:`MethodRun.status` (0..4): *refused* = the method declined to
answer (outside its training / validity domain, e.g. lrm/prm height extrapolation); *not
converged* = its iteration or training failed there; *outside image* = converged to a (row,
column) off the image; *outside tables* = its row is on a line the sensor's ephemeris tables do not
cover (``ScanlineResult.covered``; the CSM camera's own status 5)."""
SWEEP_PURPOSE = "accuracy-vs-SCOPs sweep"
"""How log lines of the background sweep's fits are prefixed (:func:`explorer._log.context`)."""
DEFAULT_METHODS = ("lrm", "prm", "mlp", "nr")
"""Methods checked at start when registered (the direct / fast ones)."""
PARAM_ALIASES = {
    "layers": ("hidden_layers", "n_hidden_layers", "layers", "n_layers", "num_layers"),
    "neurons": ("neurons", "hidden_neurons", "n_neurons", "hidden_units", "units", "width",
                "hidden_size"),
}
"""Constructor parameter names that receive the GUI's MLP layers / neurons controls, for any
method whose constructor, ``default_params`` dict or numpydoc ``Parameters`` declares them."""


@dataclass(frozen=True)
class Settings:
    """Everything the explorer's output depends on (one value per GUI control)."""

    preset: str = "WSU"
    relief_m: float = 0.0
    attitude_rate_scale: float = 1.0
    jitter_scale: float = 1.0
    scop_density: int = 100
    scp_count: int = 50_000
    methods: tuple[str, ...] = ()
    color_method: str | None = None
    mlp_layers: int = 1
    mlp_neurons: int = 10
    limit_px: float = 1.0
    colour_mode: str = "per method"
    component: str = "row"
    diff: tuple[str, str] | None = None
    """Two methods whose row-residual difference (first minus second) gets its own map."""
    aggregate: str = "mean"
    """Residual-map cell value: "mean" (signed mean of the cell's check points) or "max |residual|"
    (the signed residual of largest magnitude in the cell); :data:`explorer.panels.AGGREGATES`."""
    show_scops: bool = True
    sensor_distance: str = "compressed"
    height_exaggeration: float = 1.0
    auto_exaggeration: bool = True
    """Exaggerate heights automatically so a real DEM's relief shows (the factor is stated; the slider
    overrides it)."""
    selection: tuple = ("worst",)
    """("worst",): the SCP with the largest |residual| of ``color_method``;
    ("image", row, col): the ground point of that image point on the terrain;
    ("scp", index): that SCP (picked in a residual map)."""
    sweep: bool = True

    @property
    def scene_key(self) -> tuple:
        return (self.preset, float(self.relief_m), float(self.attitude_rate_scale), float(self.jitter_scale))


@dataclass
class FitRecord:
    """A fitted (or fit-free) method instance and what fitting cost."""

    method: BestScanlineMethod | None
    fit_s: float
    n_scops: int
    params: dict
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    unavailable: str | None = None
    """Why the method cannot run on this sensor (:func:`explorer.methods.unavailable_reason`: a search method on
    an RPC, which has no scanlines), or None; not a failure."""


@dataclass
class MethodRun:
    """One method's evaluation on the current SCPs (or why there is none)."""

    name: str
    label: str
    evaluation: Evaluation | None
    fit: FitRecord
    preview: bool = False
    """True: evaluated on the seeded preview subset (the full evaluation is computing)."""
    error: str | None = None
    key: tuple = ()
    """The evaluation's cache key (identifies its content for redraw decisions)."""

    status: np.ndarray | None = None
    """int8 (M,) aligned with ``evaluation.evaluated_index``: codes of :data:`STATUS_NAMES`."""

    @property
    def ok(self) -> bool:
        return self.evaluation is not None

    @property
    def unavailable(self) -> str | None:
        """Why the method cannot run on this sensor (its fit's :attr:`FitRecord.unavailable`), or None."""
        return self.fit.unavailable

    def status_counts(self) -> dict[str, int]:
        """Points per status name (only the non-zero ones)."""
        if self.status is None:
            return {}
        counts = np.bincount(self.status.astype(np.int64), minlength=len(STATUS_NAMES))
        return {STATUS_NAMES[k]: int(c) for k, c in enumerate(counts) if c}


@dataclass
class Selection:
    """The selected ground point and what the colour method did with it."""

    ground: np.ndarray
    exact_row: float
    exact_col: float
    source: str
    method: str | None = None
    est_row: float | None = None
    trace_rows: np.ndarray | None = None


class _LRU:
    """A small least-recently-used cache, safe to share between the GUI worker and the fit thread
    (the lock guards the dict only; values are computed outside it).

    ``size`` bounds the entries; ``max_bytes`` (with ``weigh``, the bytes of a value) also bounds the memory
    they hold: the least recently used entries go first (the newest always stays)."""

    def __init__(self, size: int, max_bytes: int | None = None, weigh: Callable[[Any], int] | None = None) -> None:
        self.size = size
        self.max_bytes = max_bytes
        self._weigh = weigh
        self._d: OrderedDict = OrderedDict()
        self._bytes: dict = {}
        self._lock = threading.Lock()

    def peek(self, key: Hashable) -> Any:
        with self._lock:
            if key in self._d:
                self._d.move_to_end(key)
                return self._d[key]
        return None

    def get_or(self, key: Hashable, make: Callable[[], Any]) -> Any:
        hit = self.peek(key)
        if hit is not None:
            return hit
        value = make()
        weight = self._weigh(value) if self._weigh is not None and self.max_bytes is not None else 0
        with self._lock:
            self._d[key] = value
            self._d.move_to_end(key)
            self._bytes[key] = weight
            while len(self._d) > self.size or (self.max_bytes is not None and len(self._d) > 1
                                               and sum(self._bytes.values()) > self.max_bytes):
                old, _ = self._d.popitem(last=False)
                self._bytes.pop(old, None)
        return value

    @property
    def nbytes(self) -> int:
        """Bytes held by the entries (as ``weigh`` counts them; 0 without it)."""
        with self._lock:
            return int(sum(self._bytes.values()))

    def __len__(self) -> int:
        return len(self._d)


def run_nbytes(run: Any) -> int:
    """Bytes of the arrays a :class:`MethodRun` holds (its evaluation's residuals and indices, its status)."""
    total = 0
    ev = getattr(run, "evaluation", None)
    for a in (getattr(ev, "residual_row", None), getattr(ev, "residual_col", None),
              getattr(ev, "evaluated_index", None), getattr(run, "status", None)):
        if isinstance(a, np.ndarray):
            total += a.nbytes
    return total


EVAL_CACHE_BYTES = 256 * 2**20
"""Memory the cached evaluations may hold (about 200 full evaluations of 50,000 SCPs, 40 of 250,000): beyond it the
least recently used are dropped and recomputed when asked again."""


def _docstring_params(cls: type) -> set[str]:
    doc = inspect.getdoc(cls) or ""
    m = re.search(r"Parameters\n-+\n(.*?)(?:\n\n[A-Z][a-z]+\n-+\n|\Z)", doc, re.S)
    if not m:
        return set()
    return set(re.findall(r"^(\w+)\s*:", m.group(1), re.M))


def accepted_params(cls: type) -> dict[str, Any]:
    """Constructor parameters a method class declares, with defaults where known.

    Looks at the ``__init__`` signature (named parameters), a ``DEFAULTS`` /
    ``default_params`` / ``defaults`` class dict and the numpydoc ``Parameters`` section
    of the class docstring.  Unknown defaults are ``inspect.Parameter.empty``.
    """
    out: dict[str, Any] = {}
    for name in _docstring_params(cls):
        out[name] = inspect.Parameter.empty
    for attr in ("DEFAULTS", "default_params", "DEFAULT_PARAMS", "defaults", "param_defaults"):
        d = getattr(cls, attr, None)
        if isinstance(d, dict):
            out.update(d)
    try:
        # the class's own constructor
        sig = inspect.signature(cls.__init__)  # type: ignore[misc]
    except (TypeError, ValueError):  # pragma: no cover
        sig = None
    if sig is not None:
        for p in list(sig.parameters.values())[1:]:
            if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL) or p.name == "scene":
                continue
            out[p.name] = p.default
    out.pop("scene", None)
    out.pop("self", None)
    return out


def control_default(control: str, names: list[str], fallback: int) -> int:
    """Initial value of a GUI control (``"layers"`` / ``"neurons"``): the default the first
    method of ``names`` declaring an accepted alias gives it, else ``fallback``."""
    reg = registry()
    for n in names:
        acc = accepted_params(reg[n])
        for alias in PARAM_ALIASES[control]:
            v = acc.get(alias, inspect.Parameter.empty)
            if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
                return int(v)
    return fallback


def gui_params(cls: type, settings: Settings) -> dict[str, Any]:
    """The GUI's MLP controls as constructor params of ``cls`` (only those it accepts)."""
    acc = accepted_params(cls)
    params: dict[str, Any] = {}
    for control, value in (("layers", settings.mlp_layers), ("neurons", settings.mlp_neurons)):
        for alias in PARAM_ALIASES[control]:
            if alias in acc:
                params[alias] = int(value)
                break
    return params


class ExplorerModel:
    """Scenes, points, fits and evaluations with caches; no GUI.

    Parameters
    ----------
    preview_after_s : float or None
        A method whose ground-to-image on all the SCPs is projected (from a probe on
        ``probe_points``) to take longer than this gets a preview on ``preview_points`` seeded
        SCPs first (:meth:`needs_preview`; the GUI's background mode only).  None: never.
    preview_points : int
        Size of the preview subset (fixed and seeded: the same points on every run).
    sweep_points : int
        SCPs (seeded subsample) used for the accuracy-vs-density sweep.
    seed : int
        Seed of the SCOP / SCP heights and of every subsample.
    scenes : mapping of str to Scene, optional
        Fixed scenes by id (real sensors loaded by :mod:`explorer.sources`); a
        ``Settings.preset`` naming one of them selects it (the relief / attitude / jitter
        controls do not apply), any other id is built as a preset.
    """

    def __init__(
        self,
        *,
        preview_after_s: float | None = 2.0,
        preview_points: int = 5_000,
        probe_points: int = 2000,
        sweep_points: int = 5000,
        seed: int = 0,
        scenes: Mapping[str, Scene] | None = None,
    ) -> None:
        self.fixed_scenes: dict[str, Scene] = dict(scenes or {})
        self.preview_after_s = preview_after_s
        self.preview_points = int(preview_points)
        self.probe_points = probe_points
        self.sweep_points = sweep_points
        self.seed = seed
        self._scenes = _LRU(8)
        self._scops = _LRU(32)
        self._scps = _LRU(4)
        self._fits = _LRU(128)
        self._evals = _LRU(64, max_bytes=EVAL_CACHE_BYTES, weigh=run_nbytes)
        self._probes = _LRU(128)
        self._scp_notes: dict[tuple, str | None] = {}
        self.counters: dict[str, int] = {"scene": 0, "scops": 0, "scps": 0, "fit": 0, "evaluate": 0}
        self.per_point_s: dict[tuple, float] = {}
        """Measured ground-to-image seconds per point by (method, params), from evaluations."""
        self.fit_seconds: dict[str, float] = {}
        """Last measured fit time per learned method (decides whether to wait for its fits)."""

    # ---------------------------------------------------------------- inputs
    def scene(self, s: Settings) -> Scene:
        """The scene of ``s.preset``: a fixed scene by that id, else the preset with the controls."""
        fixed = self.fixed_scenes.get(s.preset)
        if fixed is not None:
            return fixed

        def make() -> Scene:
            self.counters["scene"] += 1
            return build_scene(s.preset, relief_m=s.relief_m, attitude_rate_scale=s.attitude_rate_scale,
                               jitter_amplitude_scale=s.jitter_scale)
        return self._scenes.get_or(s.scene_key, make)

    def scops(self, s: Settings, density: int | None = None) -> PointSet:
        density = int(density or s.scop_density)

        def make() -> PointSet:
            self.counters["scops"] += 1
            return simulate_points(self.scene(s), density, kind="scop", seed=self.seed)
        return self._scops.get_or((s.scene_key, density), make)

    def scps(self, s: Settings) -> PointSet:
        """The check points: simulated on the scene's terrain, their exact (row, col) the sensor's own ground
        to image (:func:`sensor_truth`) -- the same points in the GUI and the export."""
        def make() -> PointSet:
            self.counters["scps"] += 1
            scene = self.scene(s)
            notes: list[str] = []
            kept = sensor_truth(scene, simulate_points(scene, int(s.scp_count), kind="scp", seed=self.seed), notes)
            self._scp_notes[(s.scene_key, int(s.scp_count))] = notes[0] if notes else None
            return kept
        return self._scps.get_or((s.scene_key, int(s.scp_count)), make)

    def scp_note(self, s: Settings) -> str | None:
        """Why check points simulated on the terrain were left out (the sensor rejected them), or None when
        every one was kept (:func:`sensor_truth`)."""
        self.scps(s)
        return self._scp_notes.get((s.scene_key, int(s.scp_count)))

    # --------------------------------------------------------------- methods
    @staticmethod
    def label(name: str) -> str:
        cls = registry().get(name)
        return f"{name} ({cls.label})" if cls is not None and cls.label and cls.label != name else name

    @staticmethod
    def fit_key(name: str, s: Settings, density: int | None = None) -> tuple:
        """Cache key of a fit: (scene, SCOP density or None, method, params)."""
        cls = registry()[name]
        density = int(density or s.scop_density)
        params = gui_params(cls, s)
        return (s.scene_key, density if cls.needs_fit else None, name, tuple(sorted(params.items())))

    def cached_fit(self, name: str, s: Settings, density: int | None = None) -> FitRecord | None:
        """The fit if it is already done (never computes)."""
        return self._fits.peek(self.fit_key(name, s, density))

    def fit(self, name: str, s: Settings, density: int | None = None, *, purpose: str | None = None) -> FitRecord:
        """Create and fit ``name`` (cached by scene, SCOPs, method and params).

        ``purpose`` (e.g. "accuracy-vs-SCOPs sweep") prefixes the log lines the fit writes, so a
        line printed by background work names the work it comes from.
        """
        density = int(density or s.scop_density)
        cls = registry()[name]
        params = gui_params(cls, s)
        key = self.fit_key(name, s, density)

        def make() -> FitRecord:
            self.counters["fit"] += 1
            scene = self.scene(s)
            reason = unavailable_reason(name, scene)
            if reason is not None:  # the sensor lacks what the method needs: said, never run on a hidden model
                return FitRecord(None, 0.0, 0, params, unavailable=reason)
            scops = self.scops(s, density) if cls.needs_fit else None
            # (warnings are not captured: catch_warnings is not thread-safe and fits run on two
            # threads; learned methods report a failed training in fit_info["converged"])
            context = f"{purpose or 'maps'}, {density} SCOPs" if cls.needs_fit else (purpose or "maps")
            try:
                with _log.context(context):
                    m = create(name, scene, **params)
                    t0 = time.perf_counter()
                    if m.needs_fit:
                        assert scops is not None
                        m.fit(scops)
                    fit_s = time.perf_counter() - t0 if m.needs_fit else 0.0
                err = None
            except Exception as exc:  # a method failing must not take the explorer down
                m, fit_s, err = None, 0.0, f"{type(exc).__name__}: {exc}"
            msgs = []
            if m is not None and m.fit_info.get("converged") is False:
                msgs.append(training_note(m.fit_info))
            if cls.needs_fit:
                self.fit_seconds[name] = fit_s
            return FitRecord(m, fit_s, len(scops) if scops is not None else 0, params, err, msgs)
        return self._fits.get_or(key, make)

    def _projection(self, name: str, rec: FitRecord, s: Settings, scps: PointSet) -> float:
        """Projected seconds of ground-to-image on all the SCPs.

        Uses the per-point time measured by an earlier full evaluation of the method when there
        is one; else (after an untimed call on 2 points: one-time costs such as loading compiled
        kernels are no per-point cost) times ``probe_points`` points and, if the naive projection exceeds
        ``preview_after_s``, 8x as many to separate the fixed overhead from the per-point cost.
        (Only whether a preview is shown first depends on it, never a shown number.)
        """
        known = self.per_point_s.get((name, tuple(sorted(rec.params.items()))))
        if known is not None:
            return known * len(scps)
        key = (s.scene_key, rec.n_scops, name, tuple(sorted(rec.params.items())), len(scps))
        method = rec.method
        limit = self.preview_after_s
        assert method is not None and limit is not None

        def timed(n: int) -> float:
            sub = scps.sample(n, self.seed + 1)
            t0 = time.perf_counter()
            method.ground_to_image(sub.ground)
            return time.perf_counter() - t0

        def make() -> float:
            n_all = len(scps)
            n1 = min(self.probe_points, n_all)
            # a first call loads the method's compiled kernels from numba's cache (0.1-1 s, once per process):
            # timed, it made a fast method look slow (a preview first, the maps complete seconds later)
            timed(min(2, n_all))
            t1 = timed(n1)
            est = t1 * n_all / max(n1, 1)
            if est <= limit or n1 == n_all:
                return est
            n2 = min(8 * n1, n_all)
            t2 = timed(n2)
            per = max(t2 - t1, 0.25 * t2) / (n2 - n1) if n2 > n1 else t2 / n2
            return t2 + per * (n_all - n2)
        return float(self._probes.get_or(key, make))

    def eval_key(self, name: str, s: Settings, density: int | None = None, max_points: int | None = None) -> tuple:
        """Cache key of an evaluation: (fit key, SCP count, subsample size or None for all SCPs)."""
        if max_points is not None and max_points >= int(s.scp_count):
            max_points = None
        return (self.fit_key(name, s, density), int(s.scp_count), max_points)

    def cached_evaluation(self, name: str, s: Settings, density: int | None = None) -> MethodRun | None:
        """The full evaluation (every SCP) if it is already done (never computes)."""
        return self._evals.peek(self.eval_key(name, s, density))

    def needs_preview(self, name: str, s: Settings, rec: FitRecord) -> bool:
        """True when the full evaluation of ``name`` is not cached and is projected to take longer
        than ``preview_after_s``: the GUI then shows the seeded preview first."""
        if (self.preview_after_s is None or rec.method is None or self.cached_evaluation(name, s) is not None
                or self.preview_points >= int(s.scp_count)):
            return False
        scps = self.scps(s)
        if len(scps) <= self.preview_points:
            return False
        return self._projection(name, rec, s, scps) > self.preview_after_s

    def evaluate(self, name: str, s: Settings, *, max_points: int | None = None,
                 density: int | None = None, fit: FitRecord | None = None) -> MethodRun:
        """Fit (cached; or use ``fit``) and evaluate ``name`` on every SCP, or on the seeded subsample
        of ``max_points`` (the preview, the sweep) -- cached.  ``fit`` must be the fit of ``name`` on
        ``density`` SCOPs (default the settings')."""
        rec = fit if fit is not None else self.fit(name, s, density)
        if rec.method is None:
            return MethodRun(name, self.label(name), None, rec, error=rec.error)
        scps = self.scps(s)
        if max_points is not None and max_points >= len(scps):
            max_points = None
        key = self.eval_key(name, s, density, max_points)

        def make() -> MethodRun:
            self.counters["evaluate"] += 1
            assert rec.method is not None
            recorder = _Recording(rec.method)
            try:
                # fit=False: fits are cached separately, so changing the SCPs never retrains
                ev = evaluate_method(cast(BestScanlineMethod, recorder), scps, max_points=max_points, seed=self.seed,
                                     fit=False)
            except Exception as exc:
                return MethodRun(name, self.label(name), None, rec, error=f"{type(exc).__name__}: {exc}")
            status = point_status(recorder.result)
            ev = dataclasses.replace(ev, n_scops=rec.n_scops, fit_s=rec.fit_s)
            if max_points is None and ev.n_evaluated >= 5000:  # large enough for the per-point time to dominate
                self.per_point_s[(name, tuple(sorted(rec.params.items())))] = ev.locate_s / ev.n_evaluated
            return MethodRun(name, self.label(name), ev, rec, preview=max_points is not None, key=key,
                             status=status)
        return self._evals.get_or(key, make)

    @staticmethod
    def sweep_densities(name: str, densities: tuple[int, ...] = SCOP_DENSITIES) -> tuple[int, ...]:
        """The SCOP densities the sweep of ``name`` visits: every one, or the first alone for a method that needs
        no fit (its result does not depend on the SCOPs)."""
        return tuple(densities) if registry()[name].needs_fit else tuple(densities[:1])

    def sweep_point(self, name: str, s: Settings, density: int,
                    get_fit: Callable[[int], FitRecord | None] | None = None) -> tuple[str, Any]:
        """One point of the sweep of ``name``: ``("ok", Evaluation)`` on ``sweep_points`` SCPs at ``density`` SCOPs,
        ``("failed", reason)`` where the fit or evaluation failed, ``("none", None)`` for a fit not ready
        (``get_fit`` returned None) or a method the sensor cannot serve (:meth:`sweep`)."""
        rec = get_fit(density) if get_fit is not None else self.fit(name, s, density, purpose=SWEEP_PURPOSE)
        if rec is None:
            return ("none", None)
        run = self.evaluate(name, s, max_points=self.sweep_points, density=density, fit=rec)
        if run.evaluation is not None:
            return ("ok", run.evaluation)
        if not run.unavailable and (run.error or rec.error):
            return ("failed", str(run.error or rec.error))
        return ("none", None)

    def sweep(self, name: str, s: Settings, densities=SCOP_DENSITIES,
              get_fit: Callable[[int], FitRecord | None] | None = None,
              failed: dict[int, str] | None = None) -> list[Evaluation]:
        """Evaluations of ``name`` at each SCOP density on ``sweep_points`` SCPs (one if it needs
        no fit).  ``get_fit(density)`` may return None for a fit not ready yet (skipped).  A density whose
        fit or evaluation failed (e.g. too few SCOPs to determine the model) has no evaluation; ``failed``,
        when given, receives its reason (density -> error text), so the panel can say why its point is
        missing."""
        points = [(d, self.sweep_point(name, s, d, get_fit)) for d in self.sweep_densities(name, densities)]
        return sweep_results(points, failed)

    def selection(self, s: Settings, runs: dict[str, MethodRun]) -> Selection:
        """Resolve ``s.selection`` and trace the colour method on it."""
        scene = self.scene(s)
        run = runs.get(s.color_method) if s.color_method else None
        sel = None
        if s.selection[0] == "worst" and run is not None and run.evaluation is not None:
            ev = run.evaluation
            res = np.abs(ev.residual_row)
            if np.isfinite(res).any():
                i = int(ev.evaluated_index[int(np.nanargmax(res))])
                scps = self.scps(s)
                sel = Selection(scps.ground[i].copy(), float(scps.row[i]), float(scps.col[i]),
                                f"worst SCP of {s.color_method}")
        if sel is None and s.selection[0] == "scp":
            scps = self.scps(s)
            i = int(s.selection[1])
            if 0 <= i < len(scps):
                sel = Selection(scps.ground[i].copy(), float(scps.row[i]), float(scps.col[i]),
                                f"SCP {i} (picked in a map)")
        if sel is None:
            if s.selection[0] == "image":
                row, col = float(s.selection[1]), float(s.selection[2])
            else:
                row, col = (scene.n_rows - 1) / 2.0, (scene.n_columns - 1) / 2.0
            g = scene.image_to_ground(np.array([row]), np.array([col]))[0]
            if not np.isfinite(g).all():
                g = scene.image_to_ground(np.array([row]), np.array([col]), height=scene.terrain.mean_height)[0]
            sel = Selection(g, row, col, "image point")
        if run is not None and run.fit.method is not None:
            sel.method = s.color_method
            try:
                r = run.fit.method.ground_to_image(sel.ground[None, :], trace=True)
                sel.est_row = float(r.row[0])
                if r.trace:
                    sel.trace_rows = np.array([float(np.asarray(a).ravel()[0]) for a in r.trace])
            except Exception:  # tracing is a nicety; the result stays valid without it
                sel.trace_rows = None
        return sel


def sweep_results(points: list[tuple[int, tuple[str, Any]]], failed: dict[int, str] | None = None) -> list[Evaluation]:
    """The evaluations of a method's sweep from its points ``(density, ExplorerModel.sweep_point(...))`` in density
    order; ``failed`` receives the reasons of the failed densities."""
    out = []
    for density, (kind, value) in points:
        if kind == "ok":
            out.append(value)
        elif kind == "failed" and failed is not None:
            failed[density] = value
    return out


def sensor_truth(scene: Any, scps: PointSet, notes: list[str] | None = None) -> PointSet:
    """The check points with the sensor's own ground to image as their exact (row, col) (the truth every
    residual is measured against); points the sensor does not project onto its image are left out, and
    ``notes`` (when given) receives how many and why (:func:`left_out_text`).  Points that
    carry the geodetic coordinates a sensor defined on them localised (an RPC: ``PointSet.geodetic``) are projected
    from those (:meth:`explorer.sensor.Sensor.project_geodetic`), not from their local ENU conversion."""
    if scps.geodetic is not None:
        proj = scene.project_geodetic(scps.geodetic[:, 0], scps.geodetic[:, 1], scps.geodetic[:, 2])
    else:
        proj = scene.project(scps.ground)
    keep = np.flatnonzero(proj.valid)
    if len(scps) and not keep.size:
        from explorer.errors import InputError

        raise InputError(f"none of the {len(scps):,} check points simulated on the terrain of "
                         f"{getattr(scene, 'name', 'the sensor')!r} projects validly onto its image by the sensor's "
                         "own ground to image (its declared validity domain or image size rejects them all): "
                         "nothing can be measured")
    if notes is not None and keep.size < len(scps):
        notes.append(left_out_text(scene, scps, np.asarray(proj.valid, bool)))
    return PointSet(proj.row[keep], proj.col[keep], scps.ground[keep], scps.time[keep], scps.grid_shape,
                    None if scps.geodetic is None else scps.geodetic[keep])


def left_out_text(scene: Any, scps: PointSet, valid: np.ndarray) -> str:
    """The check points a sensor's own ground to image rejected, in words: how many, and for an RPC which part of
    its domain they fall outside (its height range is ``HEIGHT_OFF -+ HEIGHT_SCALE`` unless the file declares one,
    widened by :data:`explorer.rpc.model.VALIDITY_MARGIN`: a terrain lower or higher than the vendor's fit is
    rejected there, not extrapolated)."""
    n, k = len(valid), int(np.count_nonzero(~valid))
    why = "outside its declared validity domain or off its image"
    rpc = getattr(scene, "rpc", None)
    if rpc is not None and scps.geodetic is not None:
        from explorer.rpc.model import VALIDITY_MARGIN

        lon, lat, h = scps.geodetic[~valid].T
        d = rpc.domain  # the declared or normalisation bounds, which the RPC widens by VALIDITY_MARGIN x scale
        mh, mlon, mlat = (VALIDITY_MARGIN * abs(v) for v in (rpc.height_scale, rpc.lon_scale, rpc.lat_scale))
        h_lo, h_hi = d.h_min - mh, d.h_max + mh
        parts = []
        out_h = (h < h_lo) | (h > h_hi)
        if out_h.any():
            lo, hi = np.min(h[out_h]), np.max(h[out_h])
            parts.append(f"{int(out_h.sum()):,} at ellipsoidal heights {lo:.0f}..{hi:.0f} m, outside the RPC's "
                         f"height range {h_lo:g}..{h_hi:g} m")
        out_box = ((lon < d.lon_min - mlon) | (lon > d.lon_max + mlon) | (lat < d.lat_min - mlat)
                   | (lat > d.lat_max + mlat))
        if out_box.any():
            parts.append(f"{int(out_box.sum()):,} outside its longitude/latitude box")
        if parts:
            why = "; ".join(parts)
    return (f"{k:,} of {n:,} check points simulated on the terrain ({100.0 * k / n:.1f} %) are left out: the "
            f"sensor's own ground to image rejects them ({why}); the maps have no check point there")


class _Recording:
    """A method seen through ``evaluate_method`` that keeps its last :class:`ScanlineResult`
    (the evaluation keeps residuals only; the status flags come from the result)."""

    def __init__(self, method: BestScanlineMethod) -> None:
        self._method = method
        self.name = method.name
        self.needs_fit = method.needs_fit
        self.result: Any = None

    def ground_to_image(self, ground: np.ndarray, **kw: Any) -> Any:
        self.result = self._method.ground_to_image(ground, **kw)
        return self.result


def training_note(info: Mapping[str, Any]) -> str:
    """What a learned method's failed training verdict means for its map, e.g. "did not reach its
    accuracy goal (validation RMSE 3.98 px > 1 px; stop: validation after 16 epochs); the map shows
    the best model reached"."""
    val = info.get("val_rmse_px")
    limit = info.get("max_val_rmse_px")
    parts = []
    if isinstance(val, float):
        parts.append(f"validation RMSE {val:.3g} px" + (f" > {limit:g} px" if isinstance(limit, (int, float)) else ""))
    if "stop_reason" in info:
        parts.append(f"stop: {info['stop_reason']}" + (f" after {info['epochs']} epochs" if "epochs" in info else ""))
    return ("did not reach its accuracy goal" + (f" ({'; '.join(parts)})" if parts else "")
            + "; the map shows the best model reached")


def point_status(result: Any) -> np.ndarray:
    """Status codes (N,) int8 of a :class:`~explorer.methods.base.ScanlineResult`
    (:data:`STATUS_NAMES`): 1 refused where the method's ``info["in_domain"]`` is False,
    else 2 where it did not converge, else 4 where its row is on a line the sensor's tables do not
    cover, else 3 where (row, col) is off the image, else 0."""
    n = len(result)
    status = np.zeros(n, np.int8)
    status[~np.asarray(result.inside, bool)] = 3
    covered = getattr(result, "covered", None)
    if covered is not None:
        status[~np.asarray(covered, bool)] = 4
    status[~np.asarray(result.converged, bool)] = 2
    dom = result.info.get("in_domain") if isinstance(result.info, dict) else None
    if dom is not None and np.shape(dom) == (n,):
        status[~np.asarray(dom, bool)] = 1
    return status


def status_text(counts: Mapping[str, int], total: int) -> str:
    """The flagged points of a run in words, e.g. ``"refused (outside its domain, e.g. height
    extrapolation): 12 (0.5%); not converged: 1 of 2,000"``; "" when every point is valid."""
    words = {"refused": "refused (outside its domain, e.g. height extrapolation)",
             "not converged": "not converged", "outside image": "outside the image",
             "outside tables": "outside the sensor's tables"}
    parts = [f"{words[k]}: {count_text(v, total)}" for k, v in counts.items() if k != "valid" and v]
    return "; ".join(parts)


def summary_markdown(runs: dict[str, MethodRun], n_scps: int) -> str:
    """A markdown table of the runs (RMSE, dr_max, CE/point, points evaluated, preview).

    No timings: the table is the same on every run with the same settings (the times are in the
    Timing panel)."""
    lines = ["| method | RMSE px | dr_max px | CE/pt | evaluated |",
             "|---|---|---|---|---|"]
    notes = []
    for n, r in runs.items():
        if r.unavailable:
            lines.append(f"| {n} | - | - | - | unavailable |")
            notes.append(f"**{n}** unavailable: {r.unavailable}")
            continue
        if not r.ok:
            lines.append(f"| {n} | - | - | - | failed |")
            notes.append(f"**{n}** failed: {r.error}")
            continue
        e = r.evaluation
        assert e is not None
        ev = f"{e.n_evaluated:,}" + (" (preview)" if r.preview else "")
        lines.append(f"| {n} | {e.rmse_px:.3g} | {e.dr_max_px:.3g} | {e.ce_evals_per_point:.1f} | {ev} |")
        if r.preview:
            notes.append(f"**{n}** is slow: a preview on a fixed seeded subset of {e.n_evaluated:,} of "
                         f"{n_scps:,} SCPs is shown while every SCP is evaluated.")
        for w in r.fit.warnings:
            notes.append(f"**{n}**: {w}")
        flagged = status_text(r.status_counts(), e.n_evaluated)
        if flagged:
            notes.append(f"**{n}**: {flagged}")
    return "\n".join(lines + [""] + [f"- {t}" for t in notes])


def safe_available() -> tuple[list[str], str | None]:
    """Registered method names, and an error text when discovering them failed."""
    try:
        return available(), None
    except Exception as exc:  # a broken method module must not stop the explorer
        try:
            return available(), f"method discovery: {type(exc).__name__}: {exc}"
        except Exception:
            return [], f"method discovery: {type(exc).__name__}: {exc}"

