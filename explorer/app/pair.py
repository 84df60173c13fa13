"""``pushbroom explore --pair LEFT RIGHT [--dem DEM]``: a stereo pair in the explorer, or ``--export DIR``.

Both images' trajectories and footprints in one 3D scene (the left sensor's frame), a selected left pixel's two
lines of sight meeting on the ground, its epipolar curve in the right image against its chord, and the maps of how
far the approximations of the epipolar geometry (straight line, local affine, resampling grid) sit from the exact
curve (``docs/stereo.md``).  The exact sensors compute; the trajectories come from each file's display scene (an
RPC's MPC scene by resection, as ``--rpc``).
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError

#: Grid step of the approximation maps' grids (pixels) and the maps' sample (rows x columns).
MAP_STEP = 300.0
MAP_SHAPE = (10, 16)


def _dem(path: str | None, datum: str | None = None) -> Any:
    if path is None:
        return None
    from explorer.terrain_io import read_dem_above_ellipsoid

    return read_dem_above_ellipsoid(path, datum=datum)  # the one DEM reader (docs/conventions.md#dem-heights)


def load_pair(left_path: str, right_path: str, dem_path: str | None = None,
              kinds: tuple[str, str] = ("auto", "auto"), dem_datum: str | None = None) -> Any:
    """The :class:`~explorer.stereo.pairview.PairView` of two files.

    ``kinds`` says what each file is (:data:`explorer.sources.SENSOR_KINDS`); ``"auto"``: a scene JSON or
    ISD by content, any other file an RPC -- so a DIMAP or DigitalGlobe file is its vendor RPC unless its kind
    is ``"dimap"`` / ``"dg"``, which takes the rigorous line-scan model of the metadata."""
    from explorer.sensor import has_line_geometry
    from explorer.sources import load_source, sensor_kind
    from explorer.stereo.pairview import pair_view

    sensors, scenes = [], []
    for path, given in zip((left_path, right_path), kinds, strict=True):
        kind = sensor_kind(path, given)
        sensor = load_source(kind, path, stand_in=False).scene  # the one loader: the model itself
        sensors.append(sensor)
        # the trajectory drawn: the sensor's own line geometry, else (an RPC) its resected MPC's orbit
        scenes.append(sensor if has_line_geometry(sensor) else load_source(kind, path, as_mpc=True).scene)
    return pair_view(sensors[0], sensors[1], left_scene=scenes[0], right_scene=scenes[1],
                     dem=_dem(dem_path, dem_datum))


def pair_panels(view: Any, selection: Any) -> tuple[Any, Any, Any]:
    """The curve panel, the approximation maps' panel and the maps (grids at the pair's height, step
    :data:`MAP_STEP`)."""
    from explorer.panels.stereo import approximation_figure, epipolar_curve_figure
    from explorer.stereo.approximation import approximation_maps
    from explorer.stereo.grids import epipolar_grids

    grids = epipolar_grids(view.left, view.right, height=view.height, step=MAP_STEP)
    maps = approximation_maps(view.left, view.right, grids=grids, shape=MAP_SHAPE,
                              heights=np.linspace(view.height - 500.0, view.height + 500.0, 9))
    return epipolar_curve_figure(selection.curve, exaggeration=1000.0), approximation_figure(maps), maps


def pair_summary(view: Any, selection: Any, maps: Any) -> dict:
    """JSON-ready numbers of the export."""
    from explorer.stereo.pairview import footprint_outlines

    left_fp, right_fp = footprint_outlines(view, per_edge=4)
    c = selection.curve
    return {
        "pair": {"left": getattr(view.left, "name", "left"), "right": getattr(view.right, "name", "right"),
                 "height_m": view.height, "dem": view.dem is not None},
        "footprints_left_enu_m": {"left": left_fp.tolist(), "right": right_fp.tolist()},
        "selected": {
            "left_pixel": list(selection.left_pixel), "right_pixel": list(selection.right_pixel),
            "ground_left_enu_m": selection.ground.tolist(), "height_m": selection.height,
            "ray_distance_m": float(selection.check.ray_distance_m[0]),
            "reprojection_px": selection.check.reprojection_px[0].tolist(),
            "curve": {"heights_m": c.heights.tolist(), "row": c.row.tolist(), "col": c.col.tolist(),
                      "chord_deviation_px": c.chord_deviation_px.tolist()},
        },
        "approximation_maps": {"grid_step_px": maps.step, "heights_m": maps.heights.tolist(),
                               "summary": maps.summary()},
    }


def export_pair(view: Any, out_dir: str | Path, row: float, col: float, log: Any = print) -> dict[str, Path]:
    """Write ``summary.json``, ``curve.csv`` and ``panels.html`` into ``out_dir`` (as a whole)."""
    from explorer.io_atomic import write_folder_atomic
    from explorer.panels.figures import figures_html
    from explorer.stereo.pairview import select

    t0 = time.perf_counter()
    sel = select(view, row, col)
    curve_fig, maps_fig, maps = pair_panels(view, sel)
    c = sel.curve
    lines = ["height_m,right_row,right_col,chord_deviation_px"]
    lines += [f"{h!r},{r!r},{cc!r},{d!r}" for h, r, cc, d in
              zip(c.heights.tolist(), c.row.tolist(), c.col.tolist(), c.chord_deviation_px.tolist(), strict=True)]
    files = {
        "summary.json": (json.dumps(pair_summary(view, sel, maps), indent=1) + "\n").encode(),
        "curve.csv": ("\n".join(lines) + "\n").encode(),
        "panels.html": figures_html(
            [("Epipolar curve of the selected pixel", curve_fig), ("Approximations vs the exact curve", maps_fig)],
            "pushbroom explorer: stereo pair",
            [f"left pixel {sel.left_pixel}, right pixel {sel.right_pixel}, height {sel.height:.2f} m"]).encode(),
    }
    out = Path(out_dir)
    written = write_folder_atomic(out, files)
    log(f"pushbroom explore --pair: exported {', '.join(files)} to {out} ({time.perf_counter() - t0:.1f} s)")
    return written


def build_pair_gui(server: Any, view: Any) -> dict[str, Any]:
    """Fill a viser server: the pair's scene, a pixel selector, the curve and maps panels.  Returns the handles
    (``"select"``: a function (row, col) that redraws the selection)."""
    from explorer.scene3d.pair import add_pair, add_pair_selection, pair_display_frame
    from explorer.stereo.pairview import footprint_outlines, select, trajectories

    outlines = footprint_outlines(view)
    tracks = trajectories(view)
    frame = pair_display_frame(outlines, tracks)
    handles: dict[str, Any] = {"scene": add_pair(server.scene, frame, outlines, tracks)}
    row0, col0 = (view.left.n_rows - 1) / 2.0, (view.left.n_columns - 1) / 2.0
    sel = select(view, row0, col0)
    handles["selection"] = add_pair_selection(server.scene, frame, sel)
    curve_fig, maps_fig, _ = pair_panels(view, sel)
    gui = server.gui
    row_in = gui.add_number("left row", initial_value=row0, min=-0.5, max=view.left.n_rows - 0.5, step=1.0)
    col_in = gui.add_number("left column", initial_value=col0, min=-0.5, max=view.left.n_columns - 0.5, step=1.0)
    status = gui.add_markdown(_status(sel))
    curve_panel = gui.add_plotly(curve_fig, aspect=0.5)
    gui.add_plotly(maps_fig, aspect=0.4)
    lock = threading.Lock()

    def redraw(row: float, col: float) -> None:
        with lock:
            try:
                new = select(view, row, col)
            except InputError as exc:
                status.content = f"**{exc}**"
                return
            for h in handles["selection"].values():
                h.remove()
            handles["selection"] = add_pair_selection(server.scene, frame, new)
            status.content = _status(new)
            from explorer.panels.stereo import epipolar_curve_figure

            curve_panel.figure = epipolar_curve_figure(new.curve, exaggeration=1000.0)

    row_in.on_update(lambda _: redraw(row_in.value, col_in.value))
    col_in.on_update(lambda _: redraw(row_in.value, col_in.value))
    handles["select"] = redraw
    return handles


def _status(sel: Any) -> str:
    return (f"left ({sel.left_pixel[0]:.1f}, {sel.left_pixel[1]:.1f}) -> right ({sel.right_pixel[0]:.2f}, "
            f"{sel.right_pixel[1]:.2f}) at {sel.height:.1f} m; curve bends "
            f"{float(sel.curve.max_chord_deviation_px):.4f} px from its chord over +-500 m")


def run_pair(args: Any) -> int:
    """``explore --pair LEFT RIGHT``: load, then ``--export`` or serve until Ctrl-C."""
    from explorer.app.server import check_listen_address

    export = getattr(args, "export", None)
    if export is None:
        check_listen_address(args.host, args.port)
    view = load_pair(args.pair[0], args.pair[1], getattr(args, "dem", None),
                     (getattr(args, "left_kind", "auto"), getattr(args, "right_kind", "auto")),
                     dem_datum=getattr(args, "dem_datum", None))
    if export is not None:
        export_pair(view, export, (view.left.n_rows - 1) / 2.0, (view.left.n_columns - 1) / 2.0)
        return 0
    import signal

    import viser

    server = viser.ViserServer(host=args.host, port=args.port, label="pushbroom explorer: pair", verbose=False)
    stop = threading.Event()
    old = signal.signal(signal.SIGTERM, lambda *_: stop.set()) if threading.current_thread() is \
        threading.main_thread() else None
    try:
        print(f"pushbroom explorer (pair): http://{args.host}:{server.get_port()}  (Ctrl-C to stop)", flush=True)
        build_pair_gui(server, view)
        while not stop.wait(0.25):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        if old is not None:
            signal.signal(signal.SIGTERM, old)
        print("pushbroom explorer: stopped", flush=True)
    return 0


__all__ = ["build_pair_gui", "export_pair", "load_pair", "pair_panels", "pair_summary", "run_pair"]
