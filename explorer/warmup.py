"""Compile (or load from numba's on-disk cache) every compiled kernel once, so that no later command compiles.

Every numba kernel of the package is declared with ``cache=True``: the machine code is written next to the
module (``__pycache__``) or, where the installed package is not writable (a wheel in a system
site-packages), to numba's user cache (``$NUMBA_CACHE_DIR``, else ``~/.cache/numba``), and later processes
load it instead of compiling.  :func:`warm_up` runs the real entry points on tiny inputs for each kind of
scene -- every preset (flat) with the compiled search methods, one paper preset with every registered
method, the ``agile`` preset with relief (DEM kernel, relief paths of the methods), a rational function
model at a height and on a DEM (serial and parallel projection loops, the inverse, the DEM walk) -- so
numba compiles each kernel for the argument types the commands use; then the data-dependent and API-only
paths (``exact``'s safeguarded solver, the branch-free residual), in a checkout the CSM camera of the test ISD;
a last step compiles directly what ``explorer/kernel_manifest.json`` lists and is still missing
(:mod:`explorer.kernel_cache`, which also shows the progress line of a command that has to compile).
``pushbroom warmup`` runs it; the set-up script calls it once.

A numba kernel is compiled per argument-type signature: the inputs here have the commands' types
(float64 arrays, tuples of floats), so one warm-up covers every scene size.
"""

from __future__ import annotations

import importlib
import sys
import threading
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any, cast

import numpy as np

__all__ = ["kernel_units", "record_unit", "steps", "warm_up", "write_manifest"]

#: Methods with compiled kernels, warmed on every preset (the others, learned or numpy, on one preset).
COMPILED_SEARCH_METHODS = ("exact", "nr", "csm-secant")


def _rpc_for_warmup():
    """A small, exactly known rational function model (affine with a height term and a mild denominator)."""
    from explorer.rpc.model import RationalFunctionModel

    row_num = np.zeros(20)
    row_den = np.zeros(20)
    col_num = np.zeros(20)
    col_den = np.zeros(20)
    row_num[[2, 1, 3]] = (-1.0, 0.02, 0.03)
    col_num[[1, 2, 3]] = (1.0, 0.01, -0.02)
    row_den[[0, 1]] = (1.0, 1e-3)
    col_den[[0, 2]] = (1.0, -1e-3)
    return RationalFunctionModel(row_num, row_den, col_num, col_den, row_offset=499.5, col_offset=499.5,
                                 lat_offset=45.0, lon_offset=5.0, height_offset=500.0, row_scale=500.0,
                                 col_scale=500.0, lat_scale=0.01, lon_scale=0.014, height_scale=500.0,
                                 image_size=(1000, 1000), source_format="warmup")


def _warm_csv() -> None:
    """The export's ``residuals.csv`` kernel (:func:`explorer.float_text.csv_lines`, with the argument types
    ``explorer.app.export.residuals_csv`` passes)."""
    import numpy as np

    from explorer.float_text import csv_lines

    out = np.zeros(1024, dtype=np.uint8)
    i64 = np.array([0, 1], dtype=np.int64)
    csv_lines(out, 0, np.full((2, 5), 0.5), 2, np.frombuffer(b"nr,", np.uint8).copy(), i64[1:] * 3, i64[1:] * 2,
              i64.copy(), i64.copy(), np.array([0.1, np.nan]), np.array([-2.0, 1e300]), i64 * 0,
              np.frombuffer(b",ok,", np.uint8).copy(), i64[1:] * 4)


def _warm_float_text() -> None:
    """:func:`explorer.float_text.g17_texts` (the Python API's exact ``%.17g`` of an array; no command uses it)."""
    import numpy as np

    from explorer.float_text import g17_texts

    g17_texts(np.array([0.1, -5e-324]))


def _warm_rpc() -> None:
    from explorer.geometry.dem_intersection import HeightGrid, intersect_segments
    from explorer.rpc import project_compiled
    from explorer.rpc.dem import localization_on_dem
    from explorer.rpc.inverse import RPCInverse
    from explorer.rpc.sensor import RPCSensor

    rpc = _rpc_for_warmup()
    rng = np.random.default_rng(0)
    row = rng.uniform(0, 999, 64)
    col = rng.uniform(0, 999, 64)
    h = rng.uniform(300, 700, 64)
    lon, lat, _ = rpc.localization(row, col, h)
    rpc.projection(lon, lat, h)
    RPCSensor(rpc).project_geodetic(lon, lat, h)  # the Sensor path's geodetic entry (its in-image pass)
    norm = (rpc.lon_offset, rpc.lon_scale, rpc.lat_offset, rpc.lat_scale, rpc.height_offset, rpc.height_scale,
            rpc.row_offset, rpc.row_scale, rpc.col_offset, rpc.col_scale)
    for parallel in (False, True):  # both loops (the choice is made by size in projection)
        project_compiled(lon, lat, h, (rpc.row_num, rpc.row_den, rpc.col_num, rpc.col_den), norm, parallel=parallel)
    # a lon/lat DEM over the scene: smooth hills, one no-data node
    lons = np.linspace(4.98, 5.02, 41)
    lats = np.linspace(45.012, 44.988, 25)
    heights = 500.0 + 150.0 * np.sin(lons[None, :] * 300.0) * np.cos(lats[:, None] * 200.0)
    heights[3, 3] = np.nan
    grid = HeightGrid.from_array(heights, lons[0], lats[0], lons[1] - lons[0], lats[1] - lats[0])
    inverse = RPCInverse.for_model(rpc, grid.z_min - 1.0, grid.z_max + 1.0)
    big = rng.uniform(0, 999, (2, 25_000))  # above the parallel threshold: the threaded loops too
    for r, c in ((row, col), (big[0], big[1])):
        inverse.localize(r, c, np.full(r.size, 500.0))
        inverse.on_dem(r, c, grid)
        localization_on_dem(rpc, r, c, grid)
    u, v = grid.to_grid(lon, lat)
    intersect_segments(grid, u, v, np.full(64, grid.z_max), u + 0.5, v + 0.3, np.full(64, grid.z_min))


def _warm_methods(scene, names, n_scops: int = 30, n_scps: int = 200) -> None:
    from explorer.methods import create, registry
    from explorer.points import simulate_points

    controls = simulate_points(scene, n_scops, kind="scop")
    checks = simulate_points(scene, n_scps, kind="scp")
    reg = registry()
    for name in names:
        cls = reg.get(name)
        if cls is None:
            continue
        method = create(name, scene)
        if cls.needs_fit:
            method.fit(controls)
        method.ground_to_image(checks.ground)


def _warm_compiled_methods(preset: str) -> None:
    from explorer.presets import build_scene

    _warm_methods(build_scene(preset), COMPILED_SEARCH_METHODS)


def _warm_one_method(name: str, scene: Any, **options: Any) -> None:
    """Warm one method on ``scene`` (a scene, or a callable that builds it)."""
    _warm_methods(scene() if callable(scene) else scene, [name], **{"n_scps": 25_000, **options})


def _warm_ortho() -> None:
    """An orthoimage block at a height and on a lon/lat DEM (its compiled bilinear height lookup)."""
    from explorer.geometry.dem_intersection import HeightGrid
    from explorer.ortho import DEMHeights, EllipsoidHeight, OrthoGeometry
    from explorer.rpc.sensor import RPCSensor

    lons, lats = np.linspace(4.98, 5.02, 41), np.linspace(45.012, 44.988, 25)
    dem = HeightGrid.from_array(np.full((lats.size, lons.size), 500.0), lons[0], lats[0], lons[1] - lons[0],
                                lats[1] - lats[0])
    for surface in (EllipsoidHeight(500.0), DEMHeights(dem)):
        _warm_ortho_block(OrthoGeometry(RPCSensor(_rpc_for_warmup()), surface))


def _warm_ortho_block(geometry: Any) -> None:
    from explorer.ortho import OrthoGrid, SourceImage, render_block

    class _Flat:
        shape = (1000, 1000)

        def sample_bilinear(self, row, col, valid):
            return np.where(valid, 1.0, np.nan)

    grid = OrthoGrid(32631, 730_000.0, 4_987_000.0, 10.0, 8, 8)
    render_block(geometry, cast("SourceImage", _Flat()), grid, slice(0, 8), slice(0, 8))


def steps() -> list[tuple[str, Callable[[], None]]]:
    """The warm-up steps, in order: (description, callable)."""
    from explorer.methods import available
    from explorer.presets import build_scene, preset_ids

    out: list[tuple[str, Callable[[], None]]] = [("the package's Python bytecode", _warm_bytecode),
                                                  ("rational function model (projection, inverse, DEM)", _warm_rpc)]
    ids = preset_ids()
    paper = "WSU" if "WSU" in ids else ids[0]
    out.append((f"{paper}: every method", lambda: _warm_methods(build_scene(paper), available(), n_scops=60)))
    out.append(("agile with 500 m relief: DEM kernel and compiled methods",
                lambda: _warm_methods(build_scene("agile", relief_m=500.0), COMPILED_SEARCH_METHODS + ("lrm", "prm"),
                                      n_scps=25_000)))
    for pid in ids:
        if pid != paper:
            out.append((f"{pid}: compiled methods", partial(_warm_compiled_methods, pid)))
    out.append(("orthorectification block", _warm_ortho))
    out.append(("stereo pair (triangulation, epipolar curve)", _warm_stereo))
    out.append(("rigorous line-scan model (DIMAP / DigitalGlobe line geometry)", _warm_linescan))
    out.append(("exact's safeguarded solver on every preset and with relief", partial(_warm_exact_everywhere, ids)))
    out.append(("kernels only the Python API calls", _warm_api))
    isd = _checkout_isd()
    if isd is not None:  # run here in a checkout; an installed wheel compiles them from the manifest below
        out.append(("USGS CSM camera (the checkout's CTX ISD)", partial(_warm_isd, isd)))
    out.append(("every other kernel of the manifest (explorer.kernel_cache)", _warm_manifest))
    return out


def compile_bytecode() -> bool:
    """Write the bytecode (``__pycache__/*.pyc``) of every module of the package, as ``pip install`` of a wheel does.

    An editable install (``./run.sh setup``) otherwise compiles each module from source on first import and writes
    its bytecode then -- or never, where ``PYTHONDONTWRITEBYTECODE`` is set: every command then compiled ~150
    modules from source on start (0.3-1 s).  ``py_compile`` writes whatever that variable says; Python reads a
    ``.pyc`` only while it matches its source, so an edited module is compiled from source again.  Returns False
    when a file could not be written (a read-only installation: nothing lost but the speed-up).
    """
    import compileall
    import os

    return bool(compileall.compile_dir(os.path.dirname(os.path.abspath(__file__)), quiet=1))


def _warm_bytecode() -> None:
    compile_bytecode()


def _warm_manifest() -> None:
    """Compile the kernels of ``explorer/kernel_manifest.json`` the steps above left out of the cache (each for
    its recorded argument types), so that :func:`explorer.kernel_cache.uncached` finds nothing missing."""
    from explorer.kernel_cache import compile_kernels, manifest, uncached

    failures = compile_kernels(uncached(list(manifest())))
    if failures:
        raise RuntimeError("; ".join(failures))


def _warm_stereo() -> None:
    """Triangulate matches of the packaged Pleiades stereo pair (both loop sizes) and trace an epipolar curve:
    the stereo kernels (``explorer.stereo``)."""
    from explorer._resources import asset_path
    from explorer.rpc import read_rpc
    from explorer.stereo import epipolar_curve, triangulate
    from explorer.stereo.triangulation import compile_parallel_twins

    left = read_rpc(asset_path("rpc", "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"))
    right = read_rpc(asset_path("rpc", "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML"))
    for n in (16, 25_000):  # below and above the parallel thresholds
        rng = np.random.default_rng(0)
        lon = left.lon_offset + rng.uniform(-0.2, 0.2, n) * left.lon_scale
        lat = left.lat_offset + rng.uniform(-0.2, 0.2, n) * left.lat_scale
        h = left.height_offset + rng.uniform(-0.2, 0.2, n) * left.height_scale
        lr, lc = left.projection(lon, lat, h)
        rr, rc = right.projection(lon, lat, h)
        triangulate(left, right, lr, lc, rr, rc)
    epipolar_curve(left, right, float(lr[0]), float(lc[0]), np.linspace(0.0, 1000.0, 5))
    _warm_generic_pair()
    compile_parallel_twins()  # the variants for a million matches, from the serial ones' argument types


def _warm_generic_pair() -> None:
    """Triangulate on two sensors that are not RPCs (scenes, rigorous models, CSM cameras: the generic path):
    the ``linear`` preset and itself turned 90 degrees about the vertical."""
    from dataclasses import replace

    from explorer.geometry.exterior import ExteriorOrientation
    from explorer.geometry.rotations import axis_angle_matrix, opk_from_rotation
    from explorer.presets import build_scene
    from explorer.stereo import triangulate

    left = build_scene("linear")
    q = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), np.radians(90.0))
    omega, phi, kappa = opk_from_rotation(q @ left.exterior.rotation(np.array([0.0]))[0])
    right = replace(left, name="warmup-right", exterior=ExteriorOrientation(
        q @ left.exterior.position_coeffs, np.array([[float(omega)], [float(phi)], [float(kappa)]])))
    g = np.linspace(0.2, 0.8, 8)
    rows, cols = np.meshgrid(g * (left.n_rows - 1), g * (left.n_columns - 1))
    ground = left.image_to_ground(rows.ravel(), cols.ravel())
    rr, rc = right.ground_to_image(ground)
    ok = np.isfinite(rr) & np.isfinite(rc)
    triangulate(left, right, rows.ravel()[ok], cols.ravel()[ok], rr[ok], rc[ok])


def _warm_exact(scene: Any, **options: Any) -> None:
    """``exact`` as a command runs it, and its safeguarded solver (:func:`_warm_exact_safeguarded`)."""
    _warm_one_method("exact", scene, **options)
    _warm_exact_safeguarded(scene)


def _warm_exact_everywhere(ids: Sequence[str]) -> None:
    """:func:`_warm_exact_safeguarded` on every preset and on ``agile`` with relief."""
    from explorer.presets import build_scene

    for pid in ids:
        _warm_exact_safeguarded(build_scene(pid))
    _warm_exact_safeguarded(build_scene("agile", relief_m=500.0))


def _warm_exact_safeguarded(scene: Any) -> None:
    """``exact``'s safeguarded iteration (the compiled general solver) runs only on the points the fast Newton
    passes leave -- a data-dependent path a first run may take on any image -- so it is run here on every point,
    with the fast evaluator's tables and without them."""
    from explorer.geometry.kernels import solve_exact
    from explorer.methods import create
    from explorer.points import simulate_points

    method = cast(Any, create("exact", scene))
    if method.kernel_params is None:  # line geometry only: no compiled MPC solver
        return
    ground = simulate_points(scene, 200, kind="scp").ground
    kw = {"window": method.window, "orient": method.orient, "tol": method.tol, "accept_step": method.accept_step,
          "max_iter": method.max_iter, "first_evaluations": method.first_evaluations}
    solve_exact(method.kernel_params, ground, method.seed, backend=method.host_backend, max_fast_passes=0, **kw)
    solve_exact(method.kernel_params, ground, method.seed, backend=method.host_backend, fast=False, **kw)


def _warm_api() -> None:
    """Kernels no command calls but the Python API does: the branch-free residual evaluator
    (``residual_and_rate(..., evaluator="fixed")``) and the Lagrange interpolation of usgscsm's own state
    (``read_isd(..., interpolation="usgscsm")`` on an ISD without velocities)."""
    from explorer.geometry.kernels import residual_and_rate
    from explorer.points import simulate_points
    from explorer.presets import build_scene
    from explorer.real import csm_kernels

    scene = build_scene("WSU")
    checks = simulate_points(scene, 64, kind="scp")
    residual_and_rate(scene, checks.ground, checks.time, evaluator="fixed")
    times = np.linspace(0.0, 1.0, 9)
    csm_kernels.lagrange_eval(times, np.stack([times, times**2, times**3], axis=1), 0.3, 8, np.empty(3))


def _warm_scene(scene) -> None:
    """What showing a scene computes besides the methods: its check points, the sensor's own ground to image of
    them (the truth every residual is measured against, ``app.model.sensor_truth``) and an image-to-ground."""
    from explorer.points import simulate_points

    simulate_points(scene, 30, kind="scop")
    checks = simulate_points(scene, 25_000, kind="scp")  # above the parallel thresholds
    scene.project(checks.ground)
    scene.project(checks.ground[:16])
    centre = np.array([(scene.n_rows - 1) / 2.0]), np.array([(scene.n_columns - 1) / 2.0])
    scene.image_to_ground(*centre)


def _rigorous_scene_for_warmup(aberration: bool = True, refraction: bool = True):
    """A rigorous line-scan scene (:class:`explorer.real.linescan.RigorousLineScanScene`, the model ``--dimap`` /
    ``--dg`` load) sampled from the default preset's orbit: ECEF ephemeris and attitude tables, no file needed."""
    from explorer.presets import build_scene, default_preset_id
    from explorer.real.linescan import (
        AttitudeTable,
        Ephemeris,
        LineScanExterior,
        RigorousLineScanScene,
        matrix_to_quaternion,
    )

    mpc = build_scene(default_preset_id())
    lo, hi = mpc.time_range()
    t = np.linspace(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), 12)
    e = mpc.frame.enu_to_ecef_rotation
    ephemeris = Ephemeris(t, mpc.frame.enu_to_ecef(mpc.exterior.position(t)), mpc.exterior.velocity(t) @ e.T)
    attitude = AttitudeTable(t, matrix_to_quaternion(np.einsum("ij,njk->nik", e, mpc.exterior.rotation(t))))
    return RigorousLineScanScene(name="warm-up rigorous", interior=mpc.interior,
                                 exterior=LineScanExterior(ephemeris, attitude, mpc.frame), timing=mpc.timing,
                                 n_rows=mpc.n_rows, terrain=mpc.terrain, frame=mpc.frame, aberration=aberration,
                                 refraction=refraction)


def _warm_linescan() -> None:
    """The compiled line geometry of the rigorous models (``--dimap``, ``--dg``; ``explorer/real/_linescan_kernel.py``):
    its serial and threaded loops (from 200,000 points), the scene's ground to image and the search methods on its
    line geometry."""
    scene = _rigorous_scene_for_warmup()
    for n in (2, 200_000):
        rows = np.linspace(0.0, scene.n_rows - 1.0, n)
        cols = np.linspace(0.0, scene.n_columns - 1.0, n)
        scene.focal_plane(scene.image_to_ground(rows, cols), scene.scanline_time(rows))
    _warm_methods(scene, ["exact", "nr"], n_scops=30, n_scps=200)


def _checkout_isd() -> Path | None:
    """The CTX test ISD of a checkout (``tests/data``, beside the package), or None in an installed wheel."""
    isd = Path(__file__).resolve().parents[1] / "tests" / "data" / "usgscsm" / "ctxLineScan.json"
    return isd if isd.is_file() else None


def _isd_scene(path: Path) -> object:
    """The sensor ``--isd`` gives: the CSM camera itself (as :func:`explorer.sources.load_source`)."""
    from explorer.real.csm_camera import read_isd
    from explorer.real.csm_sensor import csm_scene

    return csm_scene(read_isd(path))


def _warm_isd(path: Path) -> None:
    """A CSM camera as ``explore --isd`` shows it: its check points, the search methods on its own line
    geometry (the camera's residual kernels) and its MPC stand-in's check points."""
    from explorer.real.csm import scene_from_isd

    scene: Any = _isd_scene(path)
    _warm_scene(scene)
    centre = scene.image_to_ground(np.array([0.5 * scene.n_rows]), np.array([0.5 * scene.n_columns]), height=0.0)
    scene.project_geodetic(*scene.frame.enu_to_geodetic(centre))  # the geodetic entry's compiled conversion
    _warm_scene(scene_from_isd(path))
    _warm_methods(scene, ["exact", "csm-secant", "nr"], n_scops=30, n_scps=2000)


def kernel_units() -> dict[str, Callable[[], None]]:
    """Units of work whose kernels :mod:`explorer.kernel_cache` records, by name.

    ``scene`` / ``scene:relief``: every preset flat / ``agile`` with 500 m relief, its points and an
    image-to-ground; ``method:NAME``: the method fitted and run on every preset (compiled search methods;
    a kernel's argument types can differ between presets) or on the paper preset (the others);
    ``method:NAME:relief``: the same on ``agile`` with relief (``exact`` with its safeguarded solver); ``rpc``;
    ``ortho`` (at a height and on a DEM); ``stereo`` (an RPC pair, a generic pair, both kernel variants);
    ``api`` (kernels only the Python API calls); ``csv`` (the export's ``residuals.csv``);
    ``float_text`` (``g17_texts``); ``isd`` (a USGS CSM ISD: the camera's kernels; only in a checkout, which has
    the test ISDs).  A command needs the union of some
    units (:func:`explorer.kernel_cache.needed_units`).
    """
    from explorer.methods import available
    from explorer.presets import build_scene, preset_ids

    ids = preset_ids()
    paper = "WSU" if "WSU" in ids else ids[0]

    def every_preset(fn: Callable) -> Callable[[], None]:
        def run() -> None:
            for pid in ids:
                fn(build_scene(pid))
        return run

    def relief() -> object:
        return build_scene("agile", relief_m=500.0)

    units: dict[str, Callable[[], None]] = {
        "scene": every_preset(_warm_scene),
        "scene:relief": lambda: _warm_scene(relief()),
        "rpc": _warm_rpc,
        "ortho": _warm_ortho,
        "stereo": _warm_stereo,
        "linescan": _warm_linescan,
        "csv": _warm_csv,
        "float_text": _warm_float_text,
    }
    isd = _checkout_isd()
    if isd is not None:  # a checkout: recorded here, compiled by signature (_warm_manifest) where there is no ISD
        units["isd"] = partial(_warm_isd, isd)
    units["api"] = _warm_api
    for name in available():
        if name == "exact":
            units[f"method:{name}"] = every_preset(_warm_exact)
            units[f"method:{name}:relief"] = lambda: _warm_exact(relief())
            continue
        if name in COMPILED_SEARCH_METHODS:
            units[f"method:{name}"] = every_preset(partial(_warm_one_method, name))
        else:
            units[f"method:{name}"] = partial(_warm_one_method, name, partial(build_scene, paper), n_scops=60)
        units[f"method:{name}:relief"] = partial(_warm_one_method, name, relief)
    return units


def warm_up(progress: Callable[[str], None] | None = None) -> dict[str, float]:
    """Run every warm-up step; returns seconds per step.

    Parameters
    ----------
    progress : callable(str), optional
        Called with a one-line message before each step (``pushbroom warmup`` prints it).

    Returns
    -------
    dict
        Step description -> seconds; a step that failed maps to ``-1`` and its error is reported through
        ``progress`` (a warm-up failure never stops the set-up: the kernel then compiles on first use).
    """
    timings: dict[str, float] = {}
    todo = steps()
    for k, (name, fn) in enumerate(todo, 1):
        if progress is not None:
            progress(f"[{k}/{len(todo)}] warming {name}")
        t0 = time.perf_counter()
        try:
            fn()
            timings[name] = time.perf_counter() - t0
        except Exception as exc:  # noqa: BLE001 - report and continue: the kernel compiles on first use instead
            timings[name] = -1.0
            if progress is not None:
                progress(f"    failed: {type(exc).__name__}: {exc}")
    return timings


# ------------------------------------------------------------------------------ recording the manifest
def _package_dispatchers() -> dict[Any, tuple[str, str]]:
    """Every numba dispatcher defined at module level in the package: dispatcher -> (module, name)."""
    import os
    import pkgutil

    out: dict[Any, tuple[str, str]] = {}
    for info in pkgutil.walk_packages([os.path.dirname(os.path.abspath(__file__))], "explorer."):
        if info.name.startswith(("explorer.app", "explorer.notebook", "explorer.commands", "explorer.__main__")):
            continue
        try:
            module = importlib.import_module(info.name)
        except Exception:  # an optional dependency missing: its kernels are not needed either
            continue
        for name, obj in vars(module).items():
            if hasattr(obj, "overloads") and hasattr(obj, "py_func") and getattr(obj, "__module__", None) == \
                    module.__name__:
                out.setdefault(obj, (module.__name__, name))
    return out


def record_unit(unit: str) -> list[tuple[str, str, str]]:
    """Run ``unit`` (:func:`explorer.warmup.kernel_units`) and return the kernels it calls from Python:
    ``(module, name, signature)``, loaded from the cache or compiled (kernels compiled only inside another
    kernel are left out: a cached caller needs neither their cache entry nor their compilation)."""
    from numba.core import event

    fn = kernel_units()[unit]
    nested: set[tuple[Any, tuple]] = set()
    depth = threading.local()

    class _Nesting(event.Listener):
        def on_start(self, ev: Any) -> None:
            n = getattr(depth, "n", 0)
            depth.n = n + 1
            if n and str(getattr(ev.data["dispatcher"].py_func, "__module__", "")).startswith("explorer."):
                nested.add((ev.data["dispatcher"], tuple(ev.data["args"])))

        def on_end(self, ev: Any) -> None:
            depth.n = getattr(depth, "n", 1) - 1

    disps = _package_dispatchers()
    before = {d: set(d.overloads) for d in disps}
    listener = _Nesting()
    event.register("numba:compile", listener)
    try:
        fn()
    finally:
        event.unregister("numba:compile", listener)
    out = []
    for d, (module, name) in _package_dispatchers().items():
        for sig in d.overloads:
            if sig not in before.get(d, set()) and (d, tuple(sig)) not in nested:
                out.append((module, name, repr(tuple(sig))))
    return sorted(out)


def write_manifest(path: str, units: Sequence[str] | None = None) -> dict[str, list]:
    """Record every unit (:func:`record_unit`), each in a fresh process, and write the manifest module."""
    import json
    import subprocess

    from explorer.kernel_cache import manifest

    names = list(units) if units is not None else list(kernel_units())
    # recording some units keeps the others' entries
    table: dict[str, list] = {} if units is None else {
        u: [[k.module, k.name, k.signature] for k in ks] for u, ks in manifest().items()}
    for unit in names:
        code = ("import json, sys; from explorer.warmup import record_unit; "
                f"sys.stdout.write('\\n@@' + json.dumps(record_unit({unit!r})))")
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        table[unit] = [list(e) for e in json.loads(run.stdout.rsplit("\n@@", 1)[1])]
        print(f"{unit}: {len(table[unit])} kernels", file=sys.stderr, flush=True)
    write_manifest_module(path, table)
    return table


def write_manifest_module(path: str, table: dict[str, list]) -> None:
    """Write ``{unit: [(module, name, signature), ...]}`` as the manifest (JSON; each kernel listed once)."""
    import json

    index: dict[tuple, int] = {}
    for entries in table.values():
        for e in entries:
            index.setdefault(tuple(e), len(index))
    doc = {"about": "Kernels each unit of explorer.warmup.kernel_units calls from Python: 'kernels' lists "
                    "[module, name, argument types], 'units' the indices of each unit's kernels. Generated by "
                    "`python -m explorer.warmup --record` (after adding a kernel or changing its arguments); do "
                    "not edit.",
           "kernels": [list(e) for e in index],
           "units": {unit: [index[tuple(e)] for e in entries] for unit, entries in table.items()}}
    with open(path, "w", encoding="utf-8") as f:
        f.write(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":  # pragma: no cover - developer tool
    import argparse
    import os

    parser = argparse.ArgumentParser(description="record which kernels each warm-up unit calls")
    parser.add_argument("--record", action="store_true", help="rewrite explorer/kernel_manifest.json")
    parser.add_argument("--units", default=None, help="comma-separated units (default all)")
    a = parser.parse_args()
    if a.record:
        write_manifest(os.path.join(os.path.dirname(__file__), "kernel_manifest.json"),
                       a.units.split(",") if a.units else None)
