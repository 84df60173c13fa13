"""The pushbroom explorer: a viser 3D scene of the imaging geometry with Plotly
residual panels, driven by the method registry.

Two layers:

* :class:`ExplorerModel` (no viser, no plotly): builds scenes, SCOPs and SCPs,
  fits and evaluates methods through ``explorer.methods.create`` /
  ``explorer.evaluate.evaluate_method``, and caches every result by what it depends
  on -- scenes by (preset, relief, attitude rates, jitter), SCOPs by (scene,
  density), SCPs by (scene, count), fits by (scene, SCOPs, method, params),
  evaluations by (fit, SCPs, subsample).  Methods too slow for the time budget are
  evaluated on a seeded subsample whose size the panels name.
* :class:`ExplorerApp`: GUI controls in the viser panel, a worker thread that
  recomputes what the controls changed (newest request wins), the 3D scene
  (:mod:`explorer.scene3d.builders`) and the Plotly panels
  (:mod:`explorer.panels.figures`).

:func:`serve` runs it until Ctrl-C (``pushbroom explore``).  Usage, the display
frame and the responsiveness numbers: ``docs/explorer.md``; conventions:
``docs/conventions.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
import re
import signal
import sys
import threading
import time
import traceback
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explorer.evaluate import Evaluation, evaluate_method
from explorer.methods import available, create, registry
from explorer.methods.base import BestScanlineMethod
from explorer.panels import diverging_rgb
from explorer.points import PointSet, simulate_points
from explorer.presets import build_scene, default_preset_id, preset_ids
from explorer.scene import Scene

SCOP_DENSITIES = (10, 20, 30, 50, 100, 300, 500, 1000)
"""SCOP counts offered (the papers' marks)."""
SCP_COUNTS = (1_000, 10_000, 50_000, 100_000, 250_000)
COLOUR_LIMITS_PX = (0.01, 0.1, 0.5, 1.0, 2.0, 5.0, 20.0)
DEFAULT_METHODS = ("lrm", "prm", "mlp", "nr")
"""Methods checked at start when registered (the direct / fast ones)."""
PARAM_ALIASES = {
    "layers": ("hidden_layers", "n_hidden_layers", "layers", "n_layers", "num_layers"),
    "neurons": ("neurons", "hidden_neurons", "n_neurons", "hidden_units", "units", "width",
                "hidden_size"),
}
"""Constructor parameter names that receive the GUI's MLP layers / neurons controls, for any
method whose constructor, ``default_params`` dict or numpydoc ``Parameters`` declares them."""


class Superseded(Exception):
    """A newer update request arrived; the current one stops at its next checkpoint."""


# ============================================================================ model
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
    sensor_distance: str = "compressed"
    height_exaggeration: float = 1.0
    selection: tuple = ("worst",)
    """("worst",): the SCP with the largest |residual| of ``color_method``;
    ("image", row, col): the ground point of that image point on the terrain."""
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


@dataclass
class MethodRun:
    """One method's evaluation on the current SCPs (or why there is none)."""

    name: str
    label: str
    evaluation: Evaluation | None
    fit: FitRecord
    subsampled: bool = False
    error: str | None = None
    key: tuple = ()
    """The evaluation's cache key (identifies its content for redraw decisions)."""

    @property
    def ok(self) -> bool:
        return self.evaluation is not None


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
    (the lock guards the dict only; values are computed outside it)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._d: OrderedDict = OrderedDict()
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
        with self._lock:
            self._d[key] = value
            while len(self._d) > self.size:
                self._d.popitem(last=False)
        return value

    def __len__(self) -> int:
        return len(self._d)


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
        sig = inspect.signature(cls.__init__)
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
    locate_budget_s : float or None
        Ground-to-image time allowed per method on the SCPs; a method projected to need
        more (from a probe on ``probe_points``) is evaluated on a seeded subsample that
        fits the budget (at least ``min_subsample`` points).  None: always all SCPs.
    sweep_points : int
        SCPs (seeded subsample) used for the accuracy-vs-density sweep.
    seed : int
    """

    def __init__(
        self,
        *,
        locate_budget_s: float | None = 0.25,
        probe_points: int = 2000,
        min_subsample: int = 2000,
        sweep_points: int = 5000,
        seed: int = 0,
    ) -> None:
        self.locate_budget_s = locate_budget_s
        self.probe_points = probe_points
        self.min_subsample = min_subsample
        self.sweep_points = sweep_points
        self.seed = seed
        self._scenes = _LRU(8)
        self._scops = _LRU(32)
        self._scps = _LRU(4)
        self._fits = _LRU(128)
        self._evals = _LRU(64)
        self._probes = _LRU(128)
        self._plans = _LRU(256)
        self.counters: dict[str, int] = {"scene": 0, "scops": 0, "scps": 0, "fit": 0, "evaluate": 0}
        self.per_point_s: dict[tuple, float] = {}
        """Measured ground-to-image seconds per point by (method, params), from evaluations."""
        self.fit_seconds: dict[str, float] = {}
        """Last measured fit time per learned method (decides whether to wait for its fits)."""

    # ---------------------------------------------------------------- inputs
    def scene(self, s: Settings) -> Scene:
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
        def make() -> PointSet:
            self.counters["scps"] += 1
            return simulate_points(self.scene(s), int(s.scp_count), kind="scp", seed=self.seed)
        return self._scps.get_or((s.scene_key, int(s.scp_count)), make)

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

    def fit(self, name: str, s: Settings, density: int | None = None) -> FitRecord:
        """Create and fit ``name`` (cached by scene, SCOPs, method and params)."""
        density = int(density or s.scop_density)
        cls = registry()[name]
        params = gui_params(cls, s)
        key = self.fit_key(name, s, density)

        def make() -> FitRecord:
            self.counters["fit"] += 1
            scene = self.scene(s)
            scops = self.scops(s, density) if cls.needs_fit else None
            # (warnings are not captured: catch_warnings is not thread-safe and fits run on two
            # threads; learned methods report a failed training in fit_info["converged"])
            try:
                m = create(name, scene, **params)
                t0 = time.perf_counter()
                if m.needs_fit:
                    m.fit(scops)
                fit_s = time.perf_counter() - t0 if m.needs_fit else 0.0
                err = None
            except Exception as exc:  # a method failing must not take the explorer down
                m, fit_s, err = None, 0.0, f"{type(exc).__name__}: {exc}"
            msgs = []
            if m is not None and m.fit_info.get("converged") is False:
                details = ", ".join(f"{k} {m.fit_info[k]:.3g}" if isinstance(m.fit_info[k], float)
                                    else f"{k} {m.fit_info[k]}" for k in ("stop_reason", "val_rmse_px", "epochs")
                                    if k in m.fit_info)
                msgs.append("training did not converge" + (f" ({details})" if details else "")
                            + "; its points are flagged not converged")
            if cls.needs_fit:
                self.fit_seconds[name] = fit_s
            return FitRecord(m, fit_s, len(scops) if scops is not None else 0, params, err, msgs)
        return self._fits.get_or(key, make)

    def _projection(self, name: str, rec: FitRecord, s: Settings, scps: PointSet) -> tuple[float, float]:
        """(projected seconds for all SCPs, marginal seconds per point) of ground-to-image.

        Uses the per-point time measured by an earlier evaluation of the method when there is
        one; else times ``probe_points`` points and, if the naive projection exceeds the
        budget, 8x as many to separate the fixed overhead from the per-point cost (a small
        probe overstates the per-point cost of fast vectorised methods).
        """
        known = self.per_point_s.get((name, tuple(sorted(rec.params.items()))))
        if known is not None:
            return known * len(scps), known
        key = (s.scene_key, rec.n_scops, name, tuple(sorted(rec.params.items())), len(scps))

        def timed(n: int) -> float:
            sub = scps.sample(n, self.seed + 1)
            t0 = time.perf_counter()
            rec.method.ground_to_image(sub.ground)
            return time.perf_counter() - t0

        def make() -> tuple[float, float]:
            n_all = len(scps)
            n1 = min(self.probe_points, n_all)
            t1 = timed(n1)
            est = t1 * n_all / max(n1, 1)
            if est <= self.locate_budget_s or n1 == n_all:
                return est, t1 / max(n1, 1)
            n2 = min(8 * n1, n_all)
            t2 = timed(n2)
            per = max(t2 - t1, 1e-3 * t2) / (n2 - n1) if n2 > n1 else t2 / n2
            return t2 + per * (n_all - n2), per
        return self._probes.get_or(key, make)

    def evaluate(self, name: str, s: Settings, *, max_points: int | None = None,
                 density: int | None = None, fit: FitRecord | None = None) -> MethodRun:
        """Fit (cached; or use ``fit``) and evaluate ``name`` on the SCPs within the time budget
        (cached).  ``fit`` must be the fit of ``name`` on ``density`` SCOPs (default the settings')."""
        rec = fit if fit is not None else self.fit(name, s, density)
        fkey = self.fit_key(name, s, density)
        if rec.method is None:
            return MethodRun(name, self.label(name), None, rec, error=rec.error)
        scps = self.scps(s)
        if max_points is None and self.locate_budget_s is not None:
            plan_key = (fkey, int(s.scp_count))

            def plan() -> tuple[int | None]:  # decided once per input, so a revisit is a cache hit
                projected, per_point = self._projection(name, rec, s, scps)
                if projected > self.locate_budget_s:
                    return (max(self.min_subsample, int(self.locate_budget_s / per_point)),)
                return (None,)
            (max_points,) = self._plans.get_or(plan_key, plan)
        if max_points is not None and max_points >= len(scps):
            max_points = None
        key = (fkey, int(s.scp_count), max_points)

        def make() -> MethodRun:
            self.counters["evaluate"] += 1
            try:
                # fit=False: fits are cached separately, so changing the SCPs never retrains
                ev = evaluate_method(rec.method, scps, max_points=max_points, seed=self.seed, fit=False)
            except Exception as exc:
                return MethodRun(name, self.label(name), None, rec, error=f"{type(exc).__name__}: {exc}")
            ev = dataclasses.replace(ev, n_scops=rec.n_scops, fit_s=rec.fit_s)
            if ev.n_evaluated >= 5000:  # large enough for the per-point time to dominate
                self.per_point_s[(name, tuple(sorted(rec.params.items())))] = ev.locate_s / ev.n_evaluated
            return MethodRun(name, self.label(name), ev, rec, subsampled=max_points is not None, key=key)
        return self._evals.get_or(key, make)

    def sweep(self, name: str, s: Settings, densities=SCOP_DENSITIES,
              get_fit: Callable[[int], FitRecord | None] | None = None) -> list[Evaluation]:
        """Evaluations of ``name`` at each SCOP density on ``sweep_points`` SCPs (one if it needs
        no fit).  ``get_fit(density)`` may return None for a fit not ready yet (skipped)."""
        cls = registry()[name]
        out = []
        for d in (densities if cls.needs_fit else densities[:1]):
            rec = get_fit(d) if get_fit is not None else self.fit(name, s, d)
            if rec is None:
                continue
            run = self.evaluate(name, s, max_points=self.sweep_points, density=d, fit=rec)
            if run.evaluation is not None:
                out.append(run.evaluation)
        return out

    def selection(self, s: Settings, runs: dict[str, MethodRun]) -> Selection:
        """Resolve ``s.selection`` and trace the colour method on it."""
        scene = self.scene(s)
        run = runs.get(s.color_method) if s.color_method else None
        sel = None
        if s.selection[0] == "worst" and run is not None and run.ok:
            ev = run.evaluation
            res = np.abs(ev.residual_row)
            if np.isfinite(res).any():
                i = int(ev.evaluated_index[int(np.nanargmax(res))])
                scps = self.scps(s)
                sel = Selection(scps.ground[i].copy(), float(scps.row[i]), float(scps.col[i]),
                                f"worst SCP of {s.color_method}")
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


def summary_markdown(runs: dict[str, MethodRun], n_scps: int) -> str:
    """A markdown table of the runs (RMSE, dr_max, CE/point, times, subsample)."""
    lines = ["| method | RMSE px | dr_max px | CE/pt | fit s | g2i s | evaluated |",
             "|---|---|---|---|---|---|---|"]
    notes = []
    for n, r in runs.items():
        if not r.ok:
            lines.append(f"| {n} | - | - | - | - | - | failed |")
            notes.append(f"**{n}** failed: {r.error}")
            continue
        e = r.evaluation
        ev = f"{e.n_evaluated:,}" + (" (subsample)" if r.subsampled else "")
        lines.append(f"| {n} | {e.rmse_px:.3g} | {e.dr_max_px:.3g} | {e.ce_evals_per_point:.1f} | "
                     f"{e.fit_s:.3g} | {e.locate_s:.3g} | {ev} |")
        if r.subsampled:
            notes.append(f"**{n}** is slow: evaluated on a seeded subsample of {e.n_evaluated:,} of "
                         f"{n_scps:,} SCPs (time budget).")
        for w in r.fit.warnings:
            notes.append(f"**{n}**: {w}")
        if e.valid_frac < 1:
            notes.append(f"**{n}**: {100 * (1 - e.valid_frac):.2f}% of points without a valid row "
                         "(magenta)")
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


class FitPool:
    """Background threads that train methods, so a slow fit (an MLP trained by
    Levenberg-Marquardt takes seconds to minutes) never freezes the explorer.

    Jobs are keyed by :meth:`ExplorerModel.fit_key`.  The next job is the one of highest
    priority (lowest number), then lowest expected cost (the caller's estimate), then
    oldest; with two threads a long fit never holds up the quick ones, and low-priority
    jobs (priority > 0) only ever run on the first thread.  :meth:`keep`
    drops queued jobs the current settings no longer need (a running fit finishes and
    stays cached).  ``on_done(key, priority)`` is called after each job while holding
    ``cond``, so waiters see "job done" and its consequence at once.
    """

    def __init__(self, cond: threading.Condition, on_done: Callable[[Hashable, int], None],
                 threads: int = 2) -> None:
        self._cond = cond
        self._on_done = on_done
        self._jobs: dict[Hashable, tuple[int, float, int, Callable[[], Any]]] = {}
        self._counter = 0
        self.running: dict[Hashable, float] = {}
        self._closing = False
        self._threads = [threading.Thread(target=self._loop, args=(i,), name=f"explorer-fits-{i}",
                                          daemon=True) for i in range(threads)]
        for t in self._threads:
            t.start()

    def submit(self, key: Hashable, job: Callable[[], Any], priority: int = 0, cost: float = 1.0) -> None:
        with self._cond:
            if key in self._jobs or key in self.running:
                return
            self._counter += 1
            self._jobs[key] = (priority, cost, self._counter, job)
            self._cond.notify_all()

    def keep(self, keys: set) -> None:
        with self._cond:
            for k in [k for k in self._jobs if k not in keys]:
                del self._jobs[k]

    def is_pending(self, key: Hashable) -> bool:
        with self._cond:
            return key in self._jobs or key in self.running

    def queued(self, priority: int | None = None) -> int:
        """Jobs waiting (of one priority, or all)."""
        return sum(1 for j in self._jobs.values() if priority is None or j[0] == priority)

    @property
    def busy(self) -> bool:
        return bool(self._jobs) or bool(self.running)

    def wait_for(self, keys: list, deadline: float, abort: Callable[[], bool] | None = None) -> None:
        """Block until none of ``keys`` is pending, ``time.monotonic()`` passes ``deadline`` or
        ``abort()`` (checked whenever ``cond`` is notified) is true."""
        with self._cond:
            while any(self.is_pending(k) for k in keys) and not (abort is not None and abort()):
                left = deadline - time.monotonic()
                if left <= 0:
                    return
                self._cond.wait(left)

    def close(self) -> None:
        with self._cond:
            self._closing = True
            self._jobs.clear()
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=60)

    def _loop(self, index: int) -> None:
        # thread 0 takes any job; the others only priority-0 ones, so background work (the
        # accuracy sweep) never occupies more than one thread
        def ready() -> list:
            return [k for k, j in self._jobs.items() if index == 0 or j[0] == 0]

        while True:
            with self._cond:
                while not ready() and not self._closing:
                    self._cond.wait()
                if self._closing:
                    return
                key = min(ready(), key=lambda k: self._jobs[k][:3])
                priority, _, _, job = self._jobs.pop(key)
                self.running[key] = time.monotonic()
            try:
                job()
            except Exception:  # the model records method errors; anything else is a bug to show
                traceback.print_exc()
            finally:
                with self._cond:
                    del self.running[key]
                    self._on_done(key, priority)
                    self._cond.notify_all()


# ============================================================================== GUI
class ExplorerApp:
    """The explorer's GUI on a viser server.

    Parameters
    ----------
    server : viser.ViserServer
    preset : str, optional
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
    max_map_points : int
        At most this many points per method in the residual maps.
    sweep : bool
        Compute the accuracy-vs-density sweep (checkbox, can be changed in the GUI).
    fit_wait_s : float
        How long an update waits for a fit in background mode before showing it as pending.
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
        max_map_points: int = 10_000,
        sweep: bool = True,
        fit_wait_s: float = 0.5,
    ) -> None:
        import viser  # noqa: F401  (the GUI layer; the model above never needs it)

        from explorer.panels import figures as F  # noqa: N812
        from explorer.scene3d import builders as B  # noqa: N812

        self._F, self._B = F, B
        self.server = server
        self.model = model or ExplorerModel()
        self.background = background
        self.max_cloud_points = max_cloud_points
        self.max_map_points = max_map_points
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
        self.last_times: dict[str, float] = {}
        self.errors: list[str] = []
        self.url: str | None = None
        self.startup_s: float | None = None
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
        self._worker: threading.Thread | None = None
        self.fits: FitPool | None = None

        self.method_names: list[str] = []
        self.methods_ready = threading.Event()
        self._methods_gen = 0
        wanted = list(methods) if methods is not None else None
        self._build_gui(preset or default_preset_id(), scp_count, scop_density, sweep)
        self.server.scene.set_up_direction("+z")
        self.server.initial_camera.near = 0.001
        self.server.initial_camera.far = 5000.0
        if background:
            # draw the scene at once; import the method modules (torch...) meanwhile
            self.fits = FitPool(self._lock, self._fit_done)
            self._worker = threading.Thread(target=self._work, name="explorer-worker", daemon=True)
            self._worker.start()
            self.request_update()
            threading.Thread(target=self._discover_methods, args=(wanted,), name="explorer-discover",
                             daemon=True).start()
        else:
            self._discover_methods(wanted)

    # ----------------------------------------------------------------- GUI
    def _build_gui(self, preset: str, scp_count: int, scop_density: int, sweep: bool) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="medium", show_share_button=False)
        with contextlib.suppress(Exception):
            gui.main_panel.dock_left()
        h: dict[str, Any] = {}
        h["status"] = gui.add_markdown("**Status:** starting")
        h["progress"] = gui.add_progress_bar(0.0, animated=False)
        h["run"] = gui.add_button("Run", hint="recompute now (also after changes with auto update off)")
        h["auto"] = gui.add_checkbox("Update on change", True)
        with gui.add_folder("Scene"):
            h["preset"] = gui.add_dropdown("Preset", preset_ids(), initial_value=preset)
            h["relief"] = gui.add_slider("Relief (m)", 0, 3000, 100, 0)
            h["rates"] = gui.add_slider("Attitude rate scale", 0.0, 5.0, 0.1, 1.0)
            h["jitter"] = gui.add_slider("Jitter amplitude scale", 0.0, 10.0, 0.5, 1.0)
        with gui.add_folder("Points"):
            h["density"] = gui.add_dropdown("SCOPs", [str(d) for d in SCOP_DENSITIES],
                                            initial_value=str(scop_density))
            counts = sorted(set(SCP_COUNTS) | {int(scp_count)})
            h["scps"] = gui.add_dropdown("SCPs (maps)", [str(c) for c in counts],
                                         initial_value=str(int(scp_count)))
        with gui.add_folder("Methods") as folder:
            self._methods_folder = folder
            h["method_boxes"] = {}
            h["methods_note"] = gui.add_markdown("*Loading the methods...*")
            h["color_method"] = gui.add_dropdown("Colour by", self._color_options([]))
            h["layers"] = gui.add_slider("MLP layers", 1, 5, 1, 1,
                                         hint="hidden layers, for methods that take them")
            h["neurons"] = gui.add_slider("MLP neurons", 2, 50, 1, 10,
                                          hint="neurons per hidden layer, for methods that take them")
            h["limit"] = gui.add_dropdown("Colour scale +- px", [f"{v:g}" for v in COLOUR_LIMITS_PX],
                                          initial_value="1")
            h["sweep"] = gui.add_checkbox("Accuracy vs SCOPs sweep", sweep)
        with gui.add_folder("View"):
            h["distance"] = gui.add_dropdown("Sensor distance", ("compressed", "true"))
            h["exaggeration"] = gui.add_slider("Height exaggeration", 1.0, 10.0, 0.5, 1.0)
        with gui.add_folder("Selected point"):
            h["sel_mode"] = gui.add_dropdown("Select", ("worst SCP", "image point"))
            h["sel_row"] = gui.add_slider("Row", 0.0, 1e6, 0.5, 0.0)
            h["sel_col"] = gui.add_slider("Column", 0.0, 1e6, 0.5, 0.0)
            h["sel_text"] = gui.add_markdown("")
        h["cloud_text"] = gui.add_markdown("")
        self.handles = h

        self.panel = gui.add_panel()
        with self.panel.add_tab("Residual maps"):
            h["maps"] = gui.add_plotly(self._F.empty_figure("computing..."), aspect=0.5)
            h["summary"] = gui.add_markdown("")
        with self.panel.add_tab("Accuracy vs SCOPs"):
            h["accuracy"] = gui.add_plotly(self._F.empty_figure("computing..."), aspect=0.5)
        with self.panel.add_tab("Timing"):
            h["timing"] = gui.add_plotly(self._F.empty_figure("computing..."), aspect=0.5)
        with contextlib.suppress(Exception):
            self.panel.dock_right()
            self.panel.set_width(520)

        def changed(_event: Any = None) -> None:
            if getattr(self._local, "quiet", False):
                return
            if self.handles["auto"].value:
                self.request_update()

        for key in ("preset", "relief", "rates", "jitter", "density", "scps", "color_method", "layers",
                    "neurons", "limit", "distance", "exaggeration", "sweep", "sel_mode"):
            h[key].on_update(changed)

        self._changed_cb = changed

        def selection_changed(_event: Any = None) -> None:
            if getattr(self._local, "quiet", False):
                return
            with self.quiet():
                self.handles["sel_mode"].value = "image point"
            changed()

        h["sel_row"].on_update(selection_changed)
        h["sel_col"].on_update(selection_changed)
        h["run"].on_click(lambda _e: self.request_update())

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
        gui, h = self.server.gui, self.handles
        base = float(h["methods_note"].order)

        def methods_changed(_event: Any = None) -> None:
            if getattr(self._local, "quiet", False):
                return
            with self.quiet():
                h["color_method"].options = self._color_options(self.checked_methods())
            self._changed_cb()

        with self._methods_folder:
            for k, name in enumerate(names):
                cls = registry()[name]
                box = gui.add_checkbox(name, name in wanted, order=base + (k + 1) / (len(names) + 1),
                                       hint=f"{cls.label} -- {cls.reference}"[:300])
                box.on_update(methods_changed)
                h["method_boxes"][name] = box
        order = wanted + [n for n in names if n not in wanted]
        with self.quiet():
            h["color_method"].options = self._color_options(wanted)
            h["layers"].value = int(np.clip(control_default("layers", order, 1), 1, 5))
            h["neurons"].value = int(np.clip(control_default("neurons", order, 10), 2, 50))
        h["methods_note"].content = ("" if not err else f"*some method modules failed to load: {err}*")
        self.method_names = names
        self._methods_gen = self.request_update()
        self.methods_ready.set()

    def wait_methods(self, timeout: float = 120.0) -> int:
        """Block until the methods are loaded; returns the generation of the update that first
        uses them (for :meth:`wait_update`), 0 on timeout."""
        return self._methods_gen if self.methods_ready.wait(timeout) else 0

    @staticmethod
    def _color_options(methods: list[str]) -> tuple[str, ...]:
        return tuple(methods) if methods else ("(none)",)

    @contextlib.contextmanager
    def quiet(self) -> Iterator[None]:
        """Programmatic GUI changes inside this block (this thread) do not trigger updates."""
        old = getattr(self._local, "quiet", False)
        self._local.quiet = True
        try:
            yield
        finally:
            self._local.quiet = old

    def checked_methods(self) -> list[str]:
        return [n for n, b in self.handles["method_boxes"].items() if b.value]

    def settings(self) -> Settings:
        """The current control values."""
        h = self.handles
        methods = tuple(self.checked_methods())
        cm = h["color_method"].value
        if h["sel_mode"].value == "image point":
            sel = ("image", float(h["sel_row"].value), float(h["sel_col"].value))
        else:
            sel = ("worst",)
        return Settings(
            preset=h["preset"].value, relief_m=float(h["relief"].value),
            attitude_rate_scale=round(float(h["rates"].value), 6),
            jitter_scale=round(float(h["jitter"].value), 6), scop_density=int(h["density"].value),
            scp_count=int(h["scps"].value), methods=methods,
            color_method=cm if cm in methods else (methods[0] if methods else None),
            mlp_layers=int(h["layers"].value), mlp_neurons=int(h["neurons"].value),
            limit_px=float(h["limit"].value), sensor_distance=h["distance"].value,
            height_exaggeration=float(h["exaggeration"].value), selection=sel,
            sweep=bool(h["sweep"].value),
        )

    # ------------------------------------------------------------ requests
    def request_update(self) -> int:
        """Ask for a recomputation with the current controls (the newest request wins).

        Returns the request's generation number (see :meth:`wait_update`).
        """
        with self._lock:
            self._gen += 1
            gen = self._gen
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
        """Block until the methods are loaded and every requested update and every queued fit has
        finished; False on timeout."""
        end = time.monotonic() + timeout
        if not self.methods_ready.wait(timeout):
            return False
        with self._lock:
            while (self._done_gen < self._gen or self._busy
                   or (self.fits is not None and self.fits.busy)):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._lock.wait(left)
        return True

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
        if priority == 0 or not self.fits.queued() or now - self._last_trigger > 2.0:
            self._last_trigger = now
            self._gen += 1
            self._lock.notify_all()

    def _work(self) -> None:
        while True:
            with self._lock:
                while self._done_gen >= self._gen and not self._closing:
                    self._lock.wait()
                if self._closing:
                    return
                gen = self._gen
            self._run(gen)

    def _run(self, gen: int) -> None:
        with self._lock:
            self._busy = True
        try:
            self.update(self.settings(), gen)
        except Superseded:
            pass
        except Exception as exc:  # show, never die
            self.errors.append(traceback.format_exc())
            self._status(f"error: {type(exc).__name__}: {exc}", 0.0)
        finally:
            with self._lock:
                self._busy = False
                self._done_gen = max(self._done_gen, gen)
                self._lock.notify_all()

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
        out: dict[tuple[str, int | None], FitRecord | None] = {}
        missing = []
        for name, d in jobs:
            if not self.background or not registry()[name].needs_fit:
                out[(name, d)] = m.fit(name, s, d)
                continue
            out[(name, d)] = m.cached_fit(name, s, d)
            if out[(name, d)] is None:
                key = m.fit_key(name, s, d)
                cost = m.fit_seconds.get(name, 1.0) * (d or s.scop_density) / 100.0
                self.fits.submit(key, lambda n=name, dd=d: m.fit(n, s, dd), priority, cost)
                missing.append((name, d, key))
        if missing and wait_s > 0:
            keys = [k for _, _, k in missing]
            with self._lock:
                self._waiting_for = set(keys)
            try:
                self.fits.wait_for(keys, time.monotonic() + wait_s,
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
        return f"queued for training on {s.scop_density} SCOPs"

    # -------------------------------------------------------------- update
    def _put(self, key: str, handles: dict[str, Any]) -> None:
        """Remember the nodes a builder made, removing the previous ones of this group."""
        for n in [n for n in self.nodes if n.startswith(key)]:
            if n not in handles:
                with contextlib.suppress(Exception):
                    self.nodes[n].remove()
                del self.nodes[n]
        self.nodes.update(handles)

    def _changed(self, group: str, key: Hashable) -> bool:
        if self._sent.get(group) == key:
            return False
        self._sent[group] = key
        return True

    def update(self, s: Settings, gen: int | None = None) -> dict[str, float]:
        """Recompute and redraw what ``s`` changed.

        Returns
        -------
        dict
            Stage timings in seconds: scene, methods, cloud, panels, selection, total (the
            scene and panels are up to date), sweep (accuracy-vs-density, after total).
        """
        B, F, m = self._B, self._F, self.model  # noqa: N806
        times: dict[str, float] = {}
        t_start = time.perf_counter()
        self._status(f"building scene {s.preset}", 2)
        scene = m.scene(s)
        scops = m.scops(s)
        scps = m.scps(s)
        self.scene = scene
        frame_key = (s.scene_key, s.sensor_distance, s.height_exaggeration)
        if self._changed("frame", frame_key):
            self.frame = B.DisplayFrame.for_scene(scene, sensor_distance=s.sensor_distance,
                                                  height_exaggeration=s.height_exaggeration)
            with self.server.atomic():
                self._put("/ground", B.add_ground(self.server.scene, scene, self.frame))
                self._put("/orbit", B.add_orbit(self.server.scene, scene, self.frame))
            self._frame_camera(scene, (s.preset, s.sensor_distance))
            with self.quiet():
                self.handles["sel_row"].max = float(scene.n_rows - 1)
                self.handles["sel_col"].max = float(scene.n_columns - 1)
        frame = self.frame
        if self._changed("scops", (frame_key, s.scop_density)):
            self._put("/points/scops", B.add_scops(self.server.scene, frame, scops.ground))
        times["scene"] = time.perf_counter() - t_start
        self._check(gen)

        # ---- methods: fit (cached / background) and evaluate within the time budget
        t0 = time.perf_counter()
        runs: dict[str, MethodRun] = {}
        pending: dict[str, str] = {}
        wanted: set = set()
        self._status("training" if any(registry()[n].needs_fit for n in s.methods) else "evaluating", 5)
        fits = self._get_fits([(n, None) for n in s.methods], s, 0, self.fit_wait_s, gen)
        for i, name in enumerate(s.methods):
            self._status(f"{name} ({i + 1}/{len(s.methods)}) on {len(scps):,} SCPs",
                         5 + 60 * i / max(len(s.methods), 1))
            wanted.add(m.fit_key(name, s))
            rec = fits[(name, None)]
            if rec is None:
                pending[name] = self._pending_text(name, s)
            else:
                runs[name] = m.evaluate(name, s, fit=rec)
            self._check(gen)
        self.runs, self.pending = runs, pending
        times["methods"] = time.perf_counter() - t0

        # ---- SCP cloud coloured by the colour method
        t0 = time.perf_counter()
        cm = s.color_method
        run = runs.get(cm) if cm else None
        ev = run.evaluation if run is not None and run.ok else None
        ev_key = run.key if ev is not None else None
        if self._changed("scps", (frame_key, s.scp_count, cm, ev_key, s.limit_px)):
            if ev is not None:
                idx_all, res_all = np.asarray(ev.evaluated_index), np.asarray(ev.residual_row)
            else:
                idx_all, res_all = np.arange(len(scps)), np.full(len(scps), np.nan)
            pos = F.decimation_index(len(idx_all), self.max_cloud_points)
            idx, res = idx_all[pos], res_all[pos]
            colors = (diverging_rgb(res, s.limit_px) if ev is not None
                      else np.full((len(idx), 3), 200, np.uint8))
            self._put("/points/scps", B.add_points(self.server.scene, "/points/scps", frame,
                                                   scps.ground[idx], colors,
                                                   size_km=B.point_size_km(frame, len(idx))))
            self.cloud_index, self.cloud_residual = idx, res
            if ev is not None:
                what = f"coloured by **{cm}** residual (+-{s.limit_px:g} px, magenta: no valid row)"
            elif cm in pending:
                what = f"grey until **{cm}** has trained"
            else:
                what = "grey (no method to colour by)"
            n_eval = len(idx_all)
            sub = f" ({cm} evaluated on a subsample of {n_eval:,})" if n_eval < len(scps) else ""
            dec = (f"; the 3D view shows an evenly strided {len(idx):,} of {n_eval:,}"
                   if len(idx) < n_eval else "")
            self.handles["cloud_text"].content = (
                f"SCPs: {len(scps):,}{sub}, {what}{dec}. SCOPs (gold): {len(scops)}.")
        times["cloud"] = time.perf_counter() - t0
        self._check(gen)

        # ---- panels
        t0 = time.perf_counter()
        ok = {n: r.evaluation for n, r in runs.items() if r.ok}
        colors = F.method_colors(self.method_names)
        maps_key = (tuple((n, runs[n].key) for n in ok), s.limit_px, s.scop_density,
                    tuple(pending), self.methods_ready.is_set())
        if self._changed("maps", maps_key):
            fig = (F.residual_maps(ok, scps, control=scops, shape=scene.shape, limit_px=s.limit_px,
                                   max_points=self.max_map_points) if ok else
                   F.empty_figure("waiting for " + ", ".join(pending) if pending else self._no_method_text()))
            self._set_figure("maps", fig)
            self._set_figure("timing", F.timing_bars(ok, colors=colors) if ok else
                             F.empty_figure(self._no_method_text()))
            text = summary_markdown(runs, len(scps))
            if pending:
                text += "\n" + "\n".join(f"- **{n}**: {t}" for n, t in pending.items())
            self.handles["summary"].content = text
        times["panels"] = time.perf_counter() - t0
        self._check(gen)

        # ---- selected point, its scanline plane and the colour method's search path
        t0 = time.perf_counter()
        sel = m.selection(s, runs)
        self.selection = sel
        if self._changed("selection", (frame_key, sel.ground.tobytes(), sel.method, ev_key)):
            rows = np.array([0.0, (scene.n_rows - 1) / 2.0, scene.n_rows - 1.0, sel.exact_row])
            h_mean = scene.terrain.mean_height
            heights = np.array([h_mean, h_mean, h_mean, sel.ground[2]])
            names = ["first scanline (row 0)", "middle scanline", f"last scanline (row {scene.n_rows - 1})",
                     ""]
            with self.server.atomic():
                self._put("/scanlines", B.add_scanline_planes(self.server.scene, scene, frame, rows,
                                                              heights, names))
                self._put("/selected", B.add_selection(
                    self.server.scene, scene, frame, sel.ground, sel.exact_row, sel.trace_rows,
                    label=f"selected: row {sel.exact_row:.2f}, col {sel.exact_col:.2f}"))
            self._selection_text(sel)
            with self.quiet():
                if sel.source != "image point":
                    self.handles["sel_row"].value = round(sel.exact_row * 2) / 2
                    self.handles["sel_col"].value = round(sel.exact_col * 2) / 2
        times["selection"] = time.perf_counter() - t0
        self.last_update_s = time.perf_counter() - t_start
        times["total"] = self.last_update_s
        self.last_times = times
        self._status(self._done_text(runs, pending, scps), 100.0 if not pending else 70.0,
                     busy=bool(pending))
        if gen is not None:
            with self._lock:  # the scene and panels now show this request (see wait_update)
                self._completed_gen = max(self._completed_gen, gen)
                self._lock.notify_all()
        self._check(gen)

        # ---- accuracy vs SCOP density: evaluate what is trained, queue the rest (low priority)
        t0 = time.perf_counter()
        if s.sweep and s.methods:
            sweeps: dict[str, list[Evaluation]] = {}
            jobs = [(n, d) for n in s.methods for d in
                    (SCOP_DENSITIES if registry()[n].needs_fit else SCOP_DENSITIES[:1])]
            wanted |= {m.fit_key(n, s, d) for n, d in jobs}
            fits = self._get_fits(jobs, s, 1, self.fit_wait_s, gen)
            self._check(gen)
            for name in s.methods:
                sweeps[name] = m.sweep(name, s, get_fit=lambda d, n=name: fits.get((n, d)))
                self._check(gen)
            sweep_key = (s.scene_key, tuple((n, tuple((e.n_scops, e.rmse_px, e.dr_max_px) for e in v))
                                            for n, v in sweeps.items()))
            if self._changed("sweep", sweep_key):
                self.sweeps = sweeps
                self._set_figure("accuracy", F.accuracy_vs_density(sweeps, colors=colors))
        elif self._changed("sweep", ("off", bool(s.methods), self.methods_ready.is_set())):
            self.sweeps = {}
            self._set_figure("accuracy", F.empty_figure("sweep off" if s.methods else self._no_method_text()))
        if self.fits is not None:
            self.fits.keep(wanted)
        times["sweep"] = time.perf_counter() - t0
        self.last_times = times
        busy = self.fits is not None and self.fits.busy
        self._status(self._done_text(runs, pending, scps) + (" (training in the background)" if busy else ""),
                     100.0 if not busy else 85.0, busy=busy)
        return times

    def _no_method_text(self) -> str:
        return "no method checked" if self.methods_ready.is_set() else "loading the methods..."

    def _done_text(self, runs: dict[str, MethodRun], pending: dict[str, str], scps: PointSet) -> str:
        failed = [n for n, r in runs.items() if not r.ok]
        sub = [n for n, r in runs.items() if r.subsampled]
        name = self.scene.name if self.scene is not None else ""
        txt = f"{name}: updated in {self.last_update_s:.2f} s ({len(scps):,} SCPs)"
        if sub:
            txt += f"; on a subsample (slow): {', '.join(sub)}"
        if pending:
            txt += f"; training: {', '.join(pending)}"
        if failed:
            txt += f"; failed: {', '.join(failed)}"
        return txt

    def _set_figure(self, key: str, fig: Any) -> None:
        h = self.handles[key]
        h.figure = fig
        meta = fig.layout.meta
        if isinstance(meta, dict) and "height_over_width" in meta:
            # viser's client draws height = width * aspect (its docstring says width/height)
            h.aspect = float(meta["height_over_width"])

    def _selection_text(self, sel: Selection) -> None:
        lines = [f"**{sel.source}**: row {sel.exact_row:.3f}, col {sel.exact_col:.3f}, "
                 f"height {sel.ground[2]:.1f} m"]
        if sel.method is not None and sel.est_row is not None:
            err = sel.est_row - sel.exact_row
            lines.append(f"{sel.method}: row {sel.est_row:.4f} (error {err:+.3g} px)")
            if sel.trace_rows is not None and len(sel.trace_rows):
                tr = sel.trace_rows
                shown = " -> ".join(f"{r:.2f}" for r in tr[:12]) + (" -> ..." if len(tr) > 12 else "")
                lines.append(f"visited {len(tr)} scanlines: {shown}")
        self.handles["sel_text"].content = "  \n".join(lines)

    def _frame_camera(self, scene: Scene, key: Hashable) -> None:
        """Point the initial camera (and, on a new preset, every client's) at the ground and track."""
        frame = self.frame
        _, pos = self._B.track_positions(scene, 3)
        track = frame.sensor(pos)
        mid = track[1]
        look = 0.5 * mid
        flight = track[2] - track[0]
        flight[2] = 0.0
        flight /= max(np.linalg.norm(flight), 1e-12)
        side = np.cross(flight, [0.0, 0.0, 1.0])
        dist = max(np.linalg.norm(mid), frame.diagonal_km)
        view = 1.0 * side - 0.35 * flight + np.array([0.0, 0.0, 0.1])
        cam = look + 1.15 * dist * view / np.linalg.norm(view)
        far = float(max(5000.0, 4 * np.linalg.norm(cam)))
        self.server.initial_camera.far = far
        self.server.initial_camera.look_at = tuple(look)
        self.server.initial_camera.position = tuple(cam)
        if self._changed("camera", key):
            for client in self.server.get_clients().values():
                with contextlib.suppress(Exception):
                    client.camera.far = far
                    client.camera.look_at = tuple(look)
                    client.camera.position = tuple(cam)


def serve(preset: str | None = None, host: str = "127.0.0.1", port: int = 8080, *,
          methods: list[str] | None = None, ready: Callable[[ExplorerApp], None] | None = None,
          stop_event: threading.Event | None = None, **app_kwargs: Any) -> int:
    """Run the explorer until Ctrl-C / SIGTERM (or ``stop_event``), then stop cleanly.

    Prints the URL as soon as the server listens; the scene fills in as it is computed.

    Parameters
    ----------
    preset, host, port
        ``port=0`` picks a free port (the printed URL names it).
    methods : list of str, optional
        Methods checked at start (default :data:`DEFAULT_METHODS` that are registered).
    ready : callable, optional
        Called with the :class:`ExplorerApp` (its ``url`` set) once the server listens.
    stop_event : threading.Event, optional
        Stop when set (for running in a thread); Ctrl-C and SIGTERM stop the main thread.
    **app_kwargs
        Passed to :class:`ExplorerApp`.

    Returns
    -------
    int
        0 after a clean stop (worker joined, server stopped, port released).
    """
    import viser

    t0 = time.perf_counter()
    server = viser.ViserServer(host=host, port=port, label="pushbroom explorer", verbose=False)
    url = f"http://{host}:{server.get_port()}"
    print(f"pushbroom explorer: {url}  (Ctrl-C to stop)", flush=True)
    app = None
    stop = stop_event or threading.Event()
    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        loading = server.gui.add_markdown("**Loading the methods...**")
        app = ExplorerApp(server, preset=preset, methods=methods, **app_kwargs)
        loading.remove()
        app.url = url
        app.startup_s = time.perf_counter() - t0
        if ready is not None:
            ready(app)
        while not stop.wait(0.25):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        if app is not None:
            app.close()
        server.stop()
        if old is not None:
            signal.signal(signal.SIGTERM, old)
        print("pushbroom explorer: stopped", flush=True)
    return 0


__all__ = ["ExplorerApp", "ExplorerModel", "MethodRun", "Settings", "accepted_params", "gui_params",
           "serve", "summary_markdown"]
