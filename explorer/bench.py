"""The benchmark runner behind ``pushbroom bench`` and ``benchmarks/reproduce_papers.py``.

Protocol of the papers (Ahooei Nezhad et al. 2024, Remote Sensing 16:2787, Sec. 2.3 and 2.5; Sensors
24:5594, Sec. 2.3.1 and 3): per image, a regular grid of simulated check points (SCPs, five million in the
papers) and, for learned methods, regular grids of simulated control points (SCOPs: 10, 30, 50, 100), both
mapped to the ground at the scene's terrain (the mean height for the flat presets); the scanline error is
the estimated minus the exact row of each SCP, summarised by the RMSE (Eq. 4) and dr_max (Eq. 5).

Runs are ``presets x methods x SCOP counts``:

* the SCPs are simulated once per preset (``simulate_points(scene, n_scps, kind="scp")``) and the SCOPs once
  per preset and count (``kind="scop"``);
* search methods (``needs_fit`` False) do not depend on the SCOPs: they run once per preset and the run
  reports ``n_scops`` 0;
* slow methods are evaluated on a seeded random subsample of ``max_points_slow`` SCPs when more were asked
  for, and ``n_evaluated`` says so: the pixel-level searches and their interpolated variants (``ss``,
  ``bws``, ``ss-interp``, ``bws-interp``, any method whose ``exactness`` is ``"pixel"``), and any other
  method whose throughput, measured on a pilot sample, projects to more than ``slow_seconds`` (default 60 s)
  for all the SCPs.  ``locate_s_full_est`` scales the measured time to all the SCPs.

Only the method registry (:func:`explorer.methods.available`, :func:`explorer.methods.create`) and
:func:`explorer.evaluate.evaluate_method` are used, so every registered method is benchmarked the same way.
A method that raises is recorded with its ``error`` and the others go on.

Run record (one per run, JSON-ready; NaN written as null):

* ``preset``, ``method``, ``label``, ``family``, ``exactness``, ``params`` (constructor params given);
* ``n_scops`` (the requested SCOP count, 0 for search methods), ``n_scops_used`` (points of the SCOP grid
  actually built), ``n_scps`` (points of the SCP grid), ``n_scps_requested``, ``n_evaluated`` (SCPs
  evaluated), ``subsampled``, ``subsample_reason``;
* ``rmse_px``, ``dr_max_px`` (row, over the valid points), ``col_rmse_px``, ``valid_frac``,
  ``converged_frac``, ``fit_converged`` (the method's ``fit_info["converged"]``);
* ``fit_s``, ``locate_s`` (the evaluated points), ``locate_s_full_est`` (scaled to all the SCPs),
  ``ce_evals_per_point`` (mean), ``ce_evals_max``;
* ``relief_m``, ``warnings`` (messages the method emitted), ``error`` (None, or the exception), ``skipped``
  (None, or why the method cannot run on this sensor: :class:`~explorer.errors.MethodUnavailableError`; a
  skipped run is not a failure).

Conventions: ``docs/conventions.md``; the papers' tables next to ours: ``docs/results.md``.
"""

from __future__ import annotations

import inspect
import json
import math
import time
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from explorer import _log
from explorer.bench_defaults import (
    DEFAULT_MAX_POINTS_SLOW,
    DEFAULT_SCOPS,
    DEFAULT_SCPS,
    DEFAULT_SLOW_SECONDS,
)
from explorer.errors import ExplorerError, InputError, MethodUnavailableError, UnknownNameError
from explorer.evaluate import Evaluation, evaluate_method
from explorer.methods import available, create, registry
from explorer.points import PointSet, simulate_points
from explorer.presets import build_scene, preset_ids, preset_spec

BENCH_VERSION = 1
#: Methods that are always subsampled: pixel-level searches spend up to one CE per image row and point.
SLOW_METHODS = frozenset({"ss", "bws", "ss-interp", "bws-interp"})
#: The presets that are the papers' ten images (``paper`` in a preset list).
TEACHING_PRESETS = ("linear", "agile")
PILOT_POINTS = 2000
WARMUP_POINTS = 16

#: Fields every run record carries (the JSON schema of ``pushbroom bench --json``).
RUN_FIELDS = (
    "preset", "method", "n_scops", "n_scps", "n_evaluated", "rmse_px", "dr_max_px", "col_rmse_px", "fit_s",
    "locate_s", "ce_evals_per_point", "converged_frac",
)


@dataclass
class BenchResult:
    """What :func:`run_bench` returns: the JSON document and, when asked for, the evaluations.

    Attributes
    ----------
    doc : dict
        ``{"version": 1, "config": {...}, "runs": [{...}, ...]}`` (JSON-ready, NaN written as None).
    evaluations : list of Evaluation or None
        Parallel to ``doc["runs"]`` (None for failed runs) when ``keep_evaluations`` was set.
    check : dict
        Preset -> the SCPs used, when ``keep_evaluations`` was set.
    """

    doc: dict
    evaluations: list[Evaluation | None] = field(default_factory=list)
    check: dict[str, PointSet] = field(default_factory=dict)

    @property
    def runs(self) -> list[dict]:
        return self.doc["runs"]


# --------------------------------------------------------------------------- argument parsing
def split_list(spec: str | Sequence[str] | None) -> list[str]:
    """``"a,b, c"`` or ``["a", "b,c"]`` -> ``["a", "b", "c"]`` (empty items dropped)."""
    if spec is None:
        return []
    items = [spec] if isinstance(spec, str) else list(spec)
    out: list[str] = []
    for item in items:
        out.extend(s.strip() for s in str(item).split(",") if s.strip())
    return out


def resolve_presets(spec: str | Sequence[str]) -> list[str]:
    """Preset ids named by ``spec``: ids (case-insensitive), ``all`` (every preset) or ``paper`` (the ten
    images of the papers).

    Raises
    ------
    InputError
        For an unknown preset, naming the available ones.
    """
    out: list[str] = []
    for name in split_list(spec):
        if name.lower() == "all":
            names = preset_ids()
        elif name.lower() == "paper":
            names = [p for p in preset_ids() if p not in TEACHING_PRESETS]
        else:
            try:
                names = [preset_spec(name)["id"]]
            except KeyError:
                raise InputError(
                    f"unknown preset {name!r}; available: {', '.join(preset_ids())}, all, paper"
                ) from None
        out.extend(n for n in names if n not in out)
    if not out:
        raise InputError("no preset given")
    return out


def resolve_methods(spec: str | Sequence[str]) -> list[str]:
    """Method names named by ``spec``: registry names or ``all`` (every registered method).

    Raises
    ------
    InputError
        For an unknown method (naming the registered ones) or when ``all`` finds none registered.
    """
    known = available()
    out: list[str] = []
    for name in split_list(spec):
        if name.lower() == "all":
            if not known:
                raise InputError("no best-scanline method is registered yet (explorer/methods is empty)")
            names = known
        elif name in known:
            names = [name]
        else:
            raise InputError(f"unknown method {name!r}; available: {', '.join(sorted(known)) or '(none)'}, all")
        out.extend(n for n in names if n not in out)
    if not out:
        raise InputError("no method given")
    return out


def parse_counts(spec: str | Sequence[int | str], what: str = "SCOP count") -> list[int]:
    """``"10,30,50"`` -> ``[10, 30, 50]``; each must be an integer >= 4 (the smallest point grid)."""
    items = split_list([str(s) for s in spec] if not isinstance(spec, str) else spec)
    out = []
    for s in items:
        try:
            v = int(s)
        except ValueError:
            raise InputError(f"{what} must be an integer, got {s!r}") from None
        if v < 4:
            raise InputError(f"{what} must be >= 4 (a grid of at least 2 x 2 points), got {v}")
        if v not in out:
            out.append(v)
    return out


def is_slow_by_rule(name: str) -> bool:
    """True for the methods always subsampled: the pixel-level searches and their interpolated variants."""
    cls = registry()[name]
    return name in SLOW_METHODS or getattr(cls, "exactness", "") == "pixel"


# --------------------------------------------------------------------------- one run
def _clean(v):
    """JSON-ready value: numpy scalars to Python, NaN/inf to None."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _record(preset: str, name: str, n_scops: int, n_scops_used: int, check: PointSet, n_requested: int,
            relief_m: float, params: dict) -> dict:
    cls = registry()[name]
    return {
        "preset": preset, "method": name, "label": cls.label, "family": cls.family,
        "exactness": cls.exactness, "n_scops": n_scops, "n_scops_used": n_scops_used,
        "n_scps": len(check), "n_scps_requested": n_requested, "n_evaluated": 0, "subsampled": False,
        "subsample_reason": None, "rmse_px": None, "dr_max_px": None, "col_rmse_px": None, "fit_s": 0.0,
        "locate_s": None, "locate_s_full_est": None, "ce_evals_per_point": None, "ce_evals_max": None,
        "converged_frac": None, "valid_frac": None, "fit_converged": None, "relief_m": relief_m,
        "params": dict(params), "warnings": [], "error": None, "skipped": None,
    }


def _create(name: str, scene, params: dict, seed: int | None):
    """``create(name, scene, **params)``, passing ``seed`` too when given and the method takes one.

    Learned methods take a ``seed`` (the method interface); a deterministic one (least squares) may
    reject it, and is then built without it.
    """
    if seed is None or "seed" in params:
        return create(name, scene, **params)
    try:
        return create(name, scene, seed=seed, **params)
    except TypeError as exc:
        if "seed" not in str(exc):
            raise
        return create(name, scene, **params)


def _param_type_problem(value: object, default: object) -> str | None:
    """Why ``value`` cannot stand for a parameter whose default is ``default`` (None if it can)."""
    if isinstance(value, float) and not math.isfinite(value):
        return "not a finite number"
    if isinstance(default, bool):
        return None if isinstance(value, bool) else "must be true or false"
    if isinstance(default, int):
        return None if isinstance(value, int) and not isinstance(value, bool) else "must be an integer"
    if isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        return None if ok else "must be a number"
    return None


def check_method_params(scene, method_params: dict[str, dict], seed: int = 0) -> None:
    """Refuse constructor parameters a method does not take or rejects, before anything is benchmarked.

    Each method with parameters is built once on ``scene`` with them; an unknown name or a value of the wrong
    type or range is an :class:`~explorer.errors.InputError` naming ``METHOD.NAME=VALUE`` (``--param``),
    not a failed run.
    """
    reg = registry()
    for name, params in method_params.items():
        if name not in reg:
            raise UnknownNameError("method (in --param)", name, sorted(reg))
        shown = ", ".join(f"{name}.{k}={json.dumps(v)}" for k, v in params.items())
        signature = inspect.signature(reg[name].__init__)
        takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in signature.parameters.values())
        accepted = [k for k in signature.parameters if k not in ("self", "scene")]
        unknown = [k for k in params if k not in accepted]
        if unknown and not takes_any:
            raise InputError(f"--param {name}.{unknown[0]}: method {name!r} has no parameter {unknown[0]!r} "
                             f"(it takes: {', '.join(accepted) or 'none'})")
        for key, value in params.items():
            default = signature.parameters[key].default if key in signature.parameters else None
            problem = _param_type_problem(value, default)
            if problem:
                raise InputError(f"--param {name}.{key}={json.dumps(value)}: {problem}")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                _create(name, scene, params, seed if reg[name].needs_fit else None)
        except ExplorerError as exc:
            raise InputError(f"--param {shown}: {exc}") from None
        except (TypeError, ValueError, OverflowError) as exc:
            raise InputError(f"--param {shown}: refused by {name!r} ({type(exc).__name__}: {exc})") from None


def _time_locate(method, ground: np.ndarray) -> float:
    t0 = time.perf_counter()
    method.ground_to_image(ground)
    return time.perf_counter() - t0


def run_one(
    scene,
    name: str,
    check: PointSet,
    control: PointSet | None,
    *,
    preset: str,
    n_scops: int,
    n_scps_requested: int,
    seed: int = 0,
    relief_m: float = 0.0,
    max_points_slow: int = DEFAULT_MAX_POINTS_SLOW,
    slow_seconds: float = DEFAULT_SLOW_SECONDS,
    params: dict | None = None,
) -> tuple[dict, Evaluation | None]:
    """Fit (learned methods), decide on subsampling, evaluate one method on one preset.

    Returns
    -------
    record : dict
        One entry of ``runs`` (fields in the module docstring; :data:`RUN_FIELDS` always present).
        A failure (exception in the method) is recorded in ``error`` with the metrics left None.
    evaluation : Evaluation or None
    """
    params = dict(params or {})
    cls = registry()[name]
    rec = _record(preset, name, n_scops if cls.needs_fit else 0,
                  len(control) if (cls.needs_fit and control is not None) else 0,
                  check, n_scps_requested, relief_m, params)
    try:
        with warnings.catch_warnings(record=True) as caught, _log.collect_warnings() as logged:
            warnings.simplefilter("always")
            method = _create(name, scene, params, seed if cls.needs_fit else None)
            fit_s = 0.0
            if cls.needs_fit:
                t0 = time.perf_counter()
                method.fit(control)
                fit_s = time.perf_counter() - t0
                conv = method.fit_info.get("converged") if isinstance(method.fit_info, dict) else None
                rec["fit_converged"] = None if conv is None else bool(conv)
            # warm-up (JIT compilation, caches) outside every timing
            method.ground_to_image(check.ground[: min(WARMUP_POINTS, len(check))])
            max_points = None
            if len(check) > max_points_slow:
                if is_slow_by_rule(name):
                    max_points = max_points_slow
                    rec["subsample_reason"] = "pixel-level search (always subsampled)"
                else:
                    pilot = check.sample(PILOT_POINTS, seed)
                    rate = _time_locate(method, pilot.ground) / len(pilot)
                    if rate * len(check) > slow_seconds:
                        max_points = max_points_slow
                        rec["subsample_reason"] = (
                            f"pilot throughput projects {rate * len(check):.0f} s > {slow_seconds:g} s")
            ev = evaluate_method(method, check, control if cls.needs_fit else None, max_points=max_points,
                                 seed=seed, fit=False)
            ev.fit_s = fit_s
        rec["warnings"] = sorted({str(w.message) for w in caught} | set(logged))
    except (KeyboardInterrupt, MemoryError):
        raise
    except MethodUnavailableError as exc:  # the sensor lacks what the method needs: skipped, with the reason
        rec["skipped"] = str(exc)
        _log.warn(f"bench: {name} on {preset} skipped: {exc}")
        return rec, None
    except Exception as exc:  # a broken method must not stop the benchmark of the others
        rec["error"] = f"{type(exc).__name__}: {exc}"
        _log.warn(f"bench: {name} on {preset} (n_scops={n_scops}) failed: {rec['error']}")
        return rec, None
    rec.update(
        n_evaluated=ev.n_evaluated, subsampled=ev.n_evaluated < len(check), rmse_px=ev.rmse_px,
        dr_max_px=ev.dr_max_px, col_rmse_px=ev.col_rmse_px, fit_s=ev.fit_s, locate_s=ev.locate_s,
        locate_s_full_est=ev.locate_s * len(check) / max(ev.n_evaluated, 1),
        ce_evals_per_point=ev.ce_evals_per_point, ce_evals_max=ev.ce_evals_max,
        converged_frac=ev.converged_frac, valid_frac=ev.valid_frac,
    )
    return {k: _clean(v) for k, v in rec.items()}, ev


# --------------------------------------------------------------------------- the benchmark
def plan_runs(presets: Sequence[str], methods: Sequence[str], scops: Sequence[int]) -> list[tuple[str, str, int]]:
    """The ``(preset, method, n_scops)`` runs, search methods once per preset with ``n_scops`` 0."""
    reg = registry()
    runs: list[tuple[str, str, int]] = []
    for p in presets:
        for m in methods:
            if reg[m].needs_fit:
                runs.extend((p, m, k) for k in scops)
            else:
                runs.append((p, m, 0))
    return runs


def run_bench(
    presets: str | Sequence[str] = "WSU",
    methods: str | Sequence[str] = "all",
    scops: str | Sequence[int] = DEFAULT_SCOPS,
    n_scps: int = DEFAULT_SCPS,
    *,
    seed: int = 0,
    relief_m: float = 0.0,
    relief_seed: int = 0,
    attitude_rate_scale: float = 1.0,
    max_points_slow: int = DEFAULT_MAX_POINTS_SLOW,
    slow_seconds: float = DEFAULT_SLOW_SECONDS,
    method_params: dict[str, dict] | None = None,
    progress: bool = True,
    keep_evaluations: bool = False,
) -> BenchResult:
    """Benchmark methods on presets: ``presets x methods x SCOP counts``.

    Parameters
    ----------
    presets : str or sequence of str
        Preset ids, ``"all"`` or ``"paper"`` (comma-separated string or list).
    methods : str or sequence of str
        Registered method names or ``"all"``.
    scops : str or sequence of int
        SCOP counts for learned methods (the papers: 10, 30, 50, 100).
    n_scps : int
        About this many SCPs per preset (a regular grid; the exact count is reported in ``n_scps``).
    seed : int
        Seed of the subsamples and of the learned methods (passed as their ``seed`` param).
    relief_m, relief_seed : float, int
        Synthetic relief amplitude (metres) and its seed; SCOPs and SCPs then lie on the relief.
    attitude_rate_scale : float
        Multiplies the presets' body rates (0: attitude follows the orbit only).
    max_points_slow : int
        Subsample size for slow methods (see the module docstring).
    slow_seconds : float
        A method whose pilot throughput projects more than this for all the SCPs is subsampled.
    method_params : dict, optional
        Method name -> constructor params.
    progress : bool
        Show a tqdm progress bar (on stderr) over the runs.
    keep_evaluations : bool
        Also return the :class:`Evaluation` objects (with the residual arrays) and the SCPs.

    Returns
    -------
    BenchResult
        ``.doc`` is the JSON document ``{"version": 1, "config": {...}, "runs": [...]}``.

    Raises
    ------
    InputError
        Unknown preset or method, or a bad count, before anything runs.
    """
    preset_list = resolve_presets(presets)
    method_list = resolve_methods(methods)
    counts = parse_counts(scops)
    if int(n_scps) < 4:
        raise InputError(f"n_scps must be >= 4, got {n_scps}")
    if int(max_points_slow) < 1:
        raise InputError(f"max_points_slow must be >= 1, got {max_points_slow}")
    method_params = {k: dict(v) for k, v in (method_params or {}).items()}
    unknown = [m for m in method_params if m not in method_list]
    if unknown:
        raise InputError(f"params given for methods not benchmarked: {', '.join(unknown)}")
    reg = registry()
    if any(reg[m].needs_fit for m in method_list) and not counts:
        raise InputError("learned methods need at least one SCOP count")
    plan = plan_runs(preset_list, method_list, counts)
    config = {
        "presets": preset_list, "methods": method_list, "scops": counts, "n_scps_requested": int(n_scps),
        "seed": seed, "relief_m": relief_m, "relief_seed": relief_seed,
        "attitude_rate_scale": attitude_rate_scale, "max_points_slow": int(max_points_slow),
        "slow_seconds": slow_seconds, "method_params": method_params,
    }
    result = BenchResult({"version": BENCH_VERSION, "config": config, "runs": []})
    bar = _progress(len(plan), progress)
    try:
        for preset in preset_list:
            scene = build_scene(preset, relief_m=relief_m, relief_seed=relief_seed,
                                attitude_rate_scale=attitude_rate_scale)
            part = bench_scene(
                scene, preset, method_list, counts, int(n_scps), seed=seed, relief_m=relief_m,
                max_points_slow=int(max_points_slow), slow_seconds=slow_seconds, method_params=method_params,
                bar=bar, keep_evaluations=keep_evaluations,
            )
            result.doc["runs"].extend(part.runs)
            result.evaluations.extend(part.evaluations)
            result.check.update(part.check)
    finally:
        if bar is not None:
            bar.close()
    return result


def bench_scene(
    scene,
    label: str,
    methods: Sequence[str],
    scops: Sequence[int],
    n_scps: int,
    *,
    seed: int = 0,
    relief_m: float = 0.0,
    max_points_slow: int = DEFAULT_MAX_POINTS_SLOW,
    slow_seconds: float = DEFAULT_SLOW_SECONDS,
    method_params: dict[str, dict] | None = None,
    bar=None,
    keep_evaluations: bool = False,
    layers: int = 1,
) -> BenchResult:
    """The runs of :func:`run_bench` on one scene (any :class:`~explorer.scene.Scene`, e.g. a modified preset).

    Parameters
    ----------
    scene : Scene
    label : str
        Written as ``preset`` in the run records.
    methods : sequence of str
        Registered method names (already resolved).
    scops : sequence of int
        SCOP counts for the learned methods.
    n_scps : int
        About this many SCPs (per height layer).
    layers : int
        Height layers of the SCOP and SCP grids (1: on the terrain, as the papers; >1: 3-D grids spanning
        the terrain's height range, as the terrain-independent BP / RFM experiments).
    bar : tqdm, optional
        Progress bar to advance by one per run.
    Other parameters as :func:`run_bench`.

    Returns
    -------
    BenchResult
        ``doc`` holds only ``runs``.
    """
    reg = registry()
    method_params = method_params or {}
    check_method_params(scene, method_params, seed)
    result = BenchResult({"runs": []})
    if bar is not None:
        bar.set_description(f"{label}: simulating SCPs")
    check = simulate_points(scene, int(n_scps), kind="scp", layers=layers, seed=seed)
    if keep_evaluations:
        result.check[label] = check
    controls: dict[int, PointSet] = {}
    for _, name, k in plan_runs([label], methods, scops):
        if bar is not None:
            bar.set_description(f"{label} {name}" + (f" {k} SCOPs" if k else ""))
        control = None
        if reg[name].needs_fit:
            if k not in controls:
                controls[k] = simulate_points(scene, k, kind="scop", layers=layers, seed=seed)
            control = controls[k]
        rec, ev = run_one(
            scene, name, check, control, preset=label, n_scops=k, n_scps_requested=int(n_scps), seed=seed,
            relief_m=relief_m, max_points_slow=max_points_slow, slow_seconds=slow_seconds,
            params=method_params.get(name),
        )
        result.doc["runs"].append(rec)
        if keep_evaluations:
            result.evaluations.append(ev)
        if bar is not None:
            bar.update(1)
    return result


def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="run", leave=False, dynamic_ncols=True)


# --------------------------------------------------------------------------- output
def fmt(v, digits: int = 3) -> str:
    """A compact number: ``1.2e-09``, ``0.289``, ``1.49e+03``; ``-`` for None."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    v = float(v)
    if not math.isfinite(v):
        return "-"
    if v == 0:
        return "0"
    if 100 <= abs(v) < 1e7:
        return f"{v:.0f}"
    if 1e-3 <= abs(v) < 100:
        return f"{v:.{digits}g}"
    return f"{v:.{max(digits - 1, 1)}e}"


TABLE_COLUMNS = (
    ("preset", "preset"), ("method", "method"), ("n_scops", "SCOPs"), ("n_evaluated", "SCPs eval"),
    ("rmse_px", "RMSE px"), ("dr_max_px", "dr_max px"), ("col_rmse_px", "col RMSE px"), ("fit_s", "fit s"),
    ("locate_s", "locate s"), ("ce_evals_per_point", "CE/pt"), ("converged_frac", "conv"),
)


def format_table(runs: Iterable[dict]) -> str:
    """Plain-text table of run records (a failed run shows its error after the method)."""
    rows: list[tuple[list[str], str | None]] = []
    for r in runs:
        cells = []
        for key, _ in TABLE_COLUMNS:
            v = r.get(key)
            if key == "n_evaluated" and r.get("subsampled"):
                cells.append(f"{v}/{r['n_scps']}")
            else:
                cells.append(str(v) if isinstance(v, str) else fmt(v))
        rows.append((cells, f"ERROR {r['error']}" if r.get("error") else
                     f"SKIPPED {r['skipped']}" if r.get("skipped") else None))
    head = [h for _, h in TABLE_COLUMNS]
    widths = [max([len(h)] + [len(c[i]) for c, err in rows if not err]) for i, h in enumerate(head)]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(v.ljust(widths[i]) if i < 2 else v.rjust(widths[i]) for i, v in enumerate(cells))

    out = [line(head), "-" * len(line(head))]
    for cells, err in rows:
        out.append(line(cells) if not err else line(cells[:3]) + f"  {err}")
    return "\n".join(out)
