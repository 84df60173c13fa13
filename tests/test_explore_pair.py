"""``pushbroom explore --pair``: the export's numbers against rpcm, the pair's geometry in the left frame against
rpcm's localisation, and the served scene (viser on a port of the stereo range) with a pixel selector."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from explorer.cli import main
from explorer.geometry.frames import geodetic_to_ecef
from tests.stereo.pairs import PHR_PAIRS, rpcm_localise, rpcm_pair

LEFT, RIGHT = (str(p) for p in PHR_PAIRS["xml"])


@pytest.fixture(scope="module")
def view():
    from explorer.app.pair import load_pair

    return load_pair(LEFT, RIGHT)


def test_export_numbers_against_rpcm(tmp_path):
    out = tmp_path / "pair"
    assert main(["explore", "--pair", LEFT, RIGHT, "--export", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "panels.html").stat().st_size > 100_000 and (out / "curve.csv").exists()
    sel = summary["selected"]
    peer_l, peer_r = rpcm_pair()
    h = sel["height_m"]
    lon, lat = rpcm_localise(peer_l, np.array([sel["left_pixel"][0]]), np.array([sel["left_pixel"][1]]),
                             np.array([h]))
    col, row = peer_r.projection(lon, lat, h)
    assert abs(sel["right_pixel"][0] - row[0]) < 1e-6 and abs(sel["right_pixel"][1] - col[0]) < 1e-6
    assert sel["ray_distance_m"] < 1e-3 and max(sel["reprojection_px"]) < 1e-6
    heights = np.array(sel["curve"]["heights_m"])
    lon_c, lat_c = rpcm_localise(peer_l, np.full(heights.size, sel["left_pixel"][0]),
                                 np.full(heights.size, sel["left_pixel"][1]), heights)
    col_c, row_c = peer_r.projection(lon_c, lat_c, heights)
    assert np.max(np.abs(np.array(sel["curve"]["row"]) - row_c)) < 1e-6
    assert np.max(np.abs(np.array(sel["curve"]["col"]) - col_c)) < 1e-6
    assert set(summary["approximation_maps"]["summary"]) == {"straight line", "local affine", "grid",
                                                            "grid interpolation"}


def test_right_footprint_in_the_left_frame_against_rpcm(view):
    from explorer.stereo.pairview import footprint_outlines, trajectories

    _, right_fp = footprint_outlines(view, per_edge=1)  # the 4 corners and the first again
    _, peer_r = rpcm_pair()
    n_r, n_c = view.right.n_rows, view.right.n_columns
    rows = np.array([-0.5, -0.5, n_r - 0.5, n_r - 0.5])
    cols = np.array([-0.5, n_c - 0.5, n_c - 0.5, -0.5])
    h = np.full(4, view.height)
    lon, lat = rpcm_localise(peer_r, rows, cols, h)
    truth = view.left.frame.ecef_to_enu(geodetic_to_ecef(lon, lat, h))
    np.testing.assert_allclose(right_fp[:4], truth, atol=1e-3)
    left_track, right_track = trajectories(view)
    # the two tracks: one orbit, 35 s apart (about 250 km at 7 km/s), 690 km above the ground
    gap = np.linalg.norm(right_track.mean(axis=0) - left_track.mean(axis=0))
    assert 150e3 < gap < 350e3 and 600e3 < left_track[:, 2].mean() < 800e3


def test_served_scene_and_selector(view):
    viser = pytest.importorskip("viser")
    from explorer.app.pair import build_pair_gui

    server = viser.ViserServer(host="127.0.0.1", port=8163, verbose=False)
    try:
        handles = build_pair_gui(server, view)
        nodes = set(handles["scene"]) | set(handles["selection"])
        assert {"/pair/left/footprint", "/pair/right/footprint", "/pair/left/track", "/pair/right/track",
                "/pair/selected/point", "/pair/selected/left_ray", "/pair/selected/right_ray"} <= nodes
        before = dict(handles["selection"])
        handles["select"](100.0, 200.0)
        assert handles["selection"]["/pair/selected/point"] is not before["/pair/selected/point"]
        handles["select"](-50.0, 200.0)  # outside the image: a message, the last selection stays
        assert "/pair/selected/point" in handles["selection"]
    finally:
        server.stop()


def test_selection_on_a_dem(tmp_path):
    """With --dem the selected pixel's ground point is on the DEM: its height is the DEM's under it."""
    from explorer.app.pair import load_pair
    from explorer.stereo.pairview import select
    from explorer.terrain_io import read_geotiff_dem
    from tests.commands.test_stereo import _synthetic_dem

    dem_path = tmp_path / "dem.tif"
    _synthetic_dem(dem_path)
    view = load_pair(LEFT, RIGHT, str(dem_path))
    sel = select(view, 9000.0, 23000.0)
    lon, lat, h = view.left.frame.enu_to_geodetic(sel.ground[None, :])
    assert abs(h[0] - sel.height) < 1e-6
    assert read_geotiff_dem(dem_path).height(lon, lat)[0] == pytest.approx(sel.height, abs=1e-3)
    assert float(sel.check.ray_distance_m[0]) < 1e-3


def test_pair_kinds_take_the_rigorous_model_of_a_dimap(capsys):
    """``--left-kind dimap``: the pair's left sensor is the rigorous line-scan model of the metadata (the single-image
    ``--dimap``), not the vendor RPC the same file carries, which ``auto`` (and ``--right-kind rpc``) reads."""
    from explorer.app.pair import load_pair
    from explorer.real.linescan import RigorousLineScanScene
    from explorer.rpc.sensor import RPCSensor
    from explorer.sensor import Sensor

    dimap = str(Path(__file__).parent / "data" / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML")
    view = load_pair(dimap, dimap, None, ("dimap", "rpc"))
    assert isinstance(view.left, RigorousLineScanScene) and isinstance(view.right, RPCSensor)
    assert isinstance(view.left, Sensor) and view.left.n_rows == view.right.n_rows
    # the same image twice: the rigorous model and the vendor RPC see the same ground (measured here: 5.7e-4 px in
    # rows, 0.011 px in columns at column 300 -- the RPC's own approximation near the image edge); a different
    # image, or the RPC read as the left sensor, would be pixels to kilometres off
    rows, cols = np.array([100.0, 20000.0]), np.array([300.0, 30000.0])
    g = view.left.image_to_ground(rows, cols, height=200.0)
    r, c = view.right.ground_to_image(view.right.frame.geodetic_to_enu(*view.left.frame.enu_to_geodetic(g)))
    assert np.max(np.abs(r - rows)) < 0.05 and np.max(np.abs(c - cols)) < 0.05
    assert main(["explore", "--preset", "WSU", "--left-kind", "dimap", "--export", "x"]) == 2
    assert "--left-kind goes with --pair" in capsys.readouterr().err
