"""``pushbroom explore`` sources and listening address: everything is checked before a server
starts, and every problem is one :mod:`explorer.errors` error naming the input.

Real files: the shareloc Pleiades DIMAP products and their DEMs (``tests/data/rpc``,
``assets/dem``; provenance in their PROVENANCE.md).  Truths: the DIMAP's published image size
(49,826 rows x 39,951 columns), the DEM footprints (the 2018 product lies ~9 deg from the 2017
DEM), the preset table, and the operating system's own answer to a bind on a busy port.
"""

from __future__ import annotations

import argparse
import json
import os
import socket

import numpy as np
import pytest

from explorer.app.server import check_listen_address
from explorer.errors import ExplorerError, InputError, SceneFileError
from explorer.presets import build_scene, preset_ids
from explorer.sources import check_dem_covers, load_source, resolve_preset, source_from_args
from tests.real.conftest import DEM_DIR, PHR_2017, PHR_2018, RPC_DIR

DEM_2017 = DEM_DIR / "MNT_P1BP--2017030824934340CP.tif"
RPC_PHR = RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"


def _args(**kw) -> argparse.Namespace:
    base = {k: None for k in ("preset", "scene", "rpc", "dimap", "dg", "isd", "dem")}
    base.update(kw)
    return argparse.Namespace(**base)


# --------------------------------------------------------------------- presets
def test_presets_resolve_exactly_and_wrong_case_suggests_the_id():
    for pid in preset_ids():
        assert resolve_preset(pid) == pid
    with pytest.raises(InputError, match=r"case-sensitive; did you mean 'WSU'\?"):
        resolve_preset("wsu")
    with pytest.raises(InputError) as err:
        resolve_preset("bogus")
    assert "unknown preset 'bogus'" in str(err.value) and all(p in str(err.value) for p in preset_ids())
    src = source_from_args(_args())
    assert src.kind == "preset" and src.scene is None and src.label in preset_ids()


def test_one_source_only_and_dem_only_with_a_sensor_file(tmp_path):
    with pytest.raises(InputError, match="--preset and --scene"):
        source_from_args(_args(preset="WSU", scene="x.json"))
    with pytest.raises(InputError, match="--dem goes with"):
        source_from_args(_args(preset="WSU", dem=str(DEM_2017)))
    with pytest.raises(InputError, match="--dem goes with"):
        source_from_args(_args(dem=str(DEM_2017)))


# ------------------------------------------------------------------------ files
def test_missing_directory_and_unreadable_files_are_named(tmp_path):
    with pytest.raises(InputError, match=r"scene file '.*nope.json': no such file"):
        load_source("scene", str(tmp_path / "nope.json"))
    with pytest.raises(InputError, match="is a directory"):
        load_source("rpc", str(tmp_path))
    with pytest.raises(InputError, match=r"DEM '.*missing.tif': no such file"):
        load_source("dimap", str(PHR_2017), dem=str(tmp_path / "missing.tif"))
    if os.geteuid() != 0:  # root reads anything
        locked = tmp_path / "locked.json"
        locked.write_text("{}")
        locked.chmod(0)
        with pytest.raises(InputError, match="not readable"):
            load_source("scene", str(locked))


def test_malformed_scene_file_is_a_scene_file_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"name": "half a scene"}))
    with pytest.raises(SceneFileError):
        load_source("scene", str(bad))
    bad.write_text("{not json")
    with pytest.raises(ExplorerError):
        load_source("scene", str(bad))


def test_scene_json_round_trip(tmp_path):
    scene = build_scene("ISB", relief_m=300.0)
    path = tmp_path / "isb.json"
    scene.save(path)
    src = load_source("scene", str(path))
    assert src.kind == "scene" and src.label.startswith("isb.json (")
    assert (src.scene.n_rows, src.scene.n_columns) == (scene.n_rows, scene.n_columns)
    g = scene.image_to_ground(np.array([10.0, 900.0]), np.array([20.0, 700.0]))
    np.testing.assert_allclose(src.scene.image_to_ground(np.array([10.0, 900.0]), np.array([20.0, 700.0])), g,
                               atol=1e-6)


def test_dimap_with_its_dem_is_named_by_file_and_sensor():
    src = load_source("dimap", str(PHR_2017), dem=str(DEM_2017), dem_datum="egm96")
    assert src.label == f"{PHR_2017.name} (Pleiades 1B DIMAP)"
    assert (src.scene.n_rows, src.scene.n_columns) == (49826, 39951)  # the product's published size
    check_dem_covers(src.scene, str(DEM_2017))  # a height under every point of a 21 x 21 image grid
    g = src.scene.image_to_ground(np.array([0.0, 24912.5, 49825.0]), np.array([0.0, 19975.0, 39950.0]))
    assert np.isfinite(g).all()
    assert 50.0 < g[:, 2].min() and g[:, 2].max() < 400.0  # ellipsoidal heights of the Omani coast scene
    # the truth is the rigorous model itself; its vendor RPC is the stand-in, placed in the same frame
    from explorer.real.linescan import RigorousLineScanScene

    assert isinstance(src.scene, RigorousLineScanScene) and src.info["truth"].startswith("rigorous")
    assert src.stand_in is not None and src.stand_in.truth_frame == src.scene.frame
    assert src.info["dem_coverage"]["fraction"] == 1.0
    # the vendor RPC agrees with the rigorous model to well under a pixel on this product (CNES: ~0.01 px)
    row, col = src.stand_in.ground_to_image(g)
    exact_row, exact_col = src.scene.ground_to_image(g)
    assert np.max(np.abs(row - exact_row)) < 0.5 and np.max(np.abs(col - exact_col)) < 0.5


def test_dem_not_covering_the_footprint_is_rejected():
    with pytest.raises(InputError, match=r"DEM .* covers too little of the image footprint: heights at 0 of 441 "
                                         r"image points \(0.0 %, at least 50 % needed"):
        load_source("dimap", str(PHR_2018), dem=str(DEM_2017))
    with pytest.raises(InputError, match="DEM"):
        load_source("rpc", str(RPC_PHR), dem=str(DEM_2017))


def test_rpc_is_the_rpc_itself_without_scanlines():
    """``--rpc``: the truth is the RPC (no resection, no stand-in); its points are the RPC's own localisations."""
    from explorer.rpc.sensor import RPCSensor
    from explorer.sensor import has_line_geometry

    src = load_source("rpc", str(RPC_PHR))
    assert isinstance(src.scene, RPCSensor) and not has_line_geometry(src.scene) and src.stand_in is None
    assert src.info["truth"].startswith("the RPC itself") and "stand-in" not in src.label
    g = src.scene.image_to_ground(np.array([10.0, 20000.0]), np.array([30.0, 35000.0]))
    r, c = src.scene.rpc.projection(*src.scene.frame.enu_to_geodetic(g))
    assert np.max(np.abs(r - [10.0, 20000.0])) < 1e-6 and np.max(np.abs(c - [30.0, 35000.0])) < 1e-6
    # the 3D view draws an MPC fitted to it (drawing only), in the same frame, within 0.01 px of the RPC
    drawn = src.display_scene()
    assert drawn is src.display_scene() and has_line_geometry(drawn) and drawn.frame == src.scene.frame
    dr, dc = drawn.ground_to_image(g)
    assert np.max(np.abs(dr - [10.0, 20000.0])) < 0.01 and np.max(np.abs(dc - [30.0, 35000.0])) < 0.01
    with pytest.raises(InputError, match="--as-mpc goes with --rpc"):
        load_source("dimap", str(PHR_2018), as_mpc=True)


def test_rpc_as_mpc_is_the_resected_mpc_labelled_a_stand_in():
    src = load_source("rpc", str(RPC_PHR), as_mpc=True)
    assert src.kind == "rpc" and RPC_PHR.name in src.label and "RPC" in src.label and "stand-in" in src.label
    # docs/real_images.md: degree 3 on this file, 400 check points: 0.0008 px
    assert src.info["resection"]["check_rmse_px"] < 0.01 and src.info["resection"]["degree"] == 3
    assert src.scene.n_rows > 10_000 and src.scene.n_columns > 10_000
    # the MPC is labelled a stand-in, and the RPC itself is measured against it (what the fit costs, as a map):
    # the resection's own check points say 0.0008 px RMS, so at the scene's points it is far below a pixel
    assert "stand-in" in src.info["truth"] and src.stand_in is not None
    rng = np.random.default_rng(2)
    rows, cols = rng.uniform(0, src.scene.n_rows - 1, 300), rng.uniform(0, src.scene.n_columns - 1, 300)
    g = src.scene.image_to_ground(rows, cols, height=src.scene.terrain.mean_height)
    r, c = src.stand_in.ground_to_image(g)
    assert np.max(np.abs(r - rows)) < 0.01 and np.max(np.abs(c - cols)) < 0.01


def test_dem_covering_most_of_the_footprint_is_used_and_its_coverage_stated():
    """The public 2018 Pleiades DIMAP with its own DEM, which misses a few image corners: the DEM is used, the
    SCPs are simulated where it has heights (each on the DEM surface), and the covered fraction is stated."""
    from explorer.points import simulate_points

    src = load_source("dimap", str(PHR_2018), dem=str(DEM_DIR / "MNT_P1BP--2018122638935449CP.tif"))
    cov = src.info["dem_coverage"]
    assert 0.5 <= cov["fraction"] < 1.0 and cov["grid_points"] == 441
    assert cov["covered_points"] == round(cov["fraction"] * 441)
    scps = simulate_points(src.scene, 400, kind="scp")
    assert 0 < len(scps) < 400 * 1.2
    z = src.scene.terrain.height(scps.ground[:, 0], scps.ground[:, 1])
    np.testing.assert_allclose(scps.ground[:, 2], z, atol=1e-3)  # on the DEM, nowhere else
    row, col = src.scene.ground_to_image(scps.ground)  # and the rigorous model's own image points
    np.testing.assert_allclose(row, scps.row, atol=1e-6)
    np.testing.assert_allclose(col, scps.col, atol=1e-6)


def test_scops_are_the_chosen_count_where_the_dem_misses_part_of_the_footprint():
    """Issue 24: the SCOP count is the one chosen.  The 2018 DEM misses ~5 % of the footprint: the plain grid of 100
    nodes kept 92 SCOPs; now every chosen count is met exactly, each SCOP on the DEM surface at the rigorous model's
    own image point, the same SCOPs on every call, spread over the image (every quarter holds some)."""
    from explorer.points import image_grid, simulate_points

    src = load_source("dimap", str(PHR_2018), dem=str(DEM_DIR / "MNT_P1BP--2018122638935449CP.tif"), stand_in=False)
    scene = src.scene
    assert len(image_grid(scene, 100)) < 100  # the plain grid loses nodes here (the case under test)
    for n in (50, 100, 300, 1000):
        scops = simulate_points(scene, n, kind="scop")
        assert len(scops) == n
        z = scene.terrain.height(scops.ground[:, 0], scops.ground[:, 1])
        np.testing.assert_allclose(scops.ground[:, 2], z, atol=1e-3)
        row, col = scene.ground_to_image(scops.ground)
        np.testing.assert_allclose(row, scops.row, atol=1e-6)
        np.testing.assert_allclose(col, scops.col, atol=1e-6)
        assert len(np.unique(np.c_[scops.row, scops.col], axis=0)) == n
        top, left = scops.row < scene.n_rows / 2, scops.col < scene.n_columns / 2
        assert all(np.any(a & b) for a in (top, ~top) for b in (left, ~left))
    again = simulate_points(scene, 100, kind="scop")
    np.testing.assert_array_equal(again.ground, simulate_points(scene, 100, kind="scop").ground)


def test_isd_needs_the_csm_reader_or_loads_a_scene():
    isd_dir = RPC_DIR.parent / "usgscsm"
    try:
        from explorer.real.csm import scene_from_isd
    except ImportError:
        with pytest.raises(InputError, match="explorer.real.csm"):
            load_source("isd", str(PHR_2017))
        return

    files = sorted(isd_dir.glob("*LineScan*.json")) if isd_dir.exists() else []
    if not files:
        pytest.skip("no ISD test file in tests/data/usgscsm")
    src = load_source("isd", str(files[0]))
    ref = scene_from_isd(files[0])
    assert (src.scene.n_rows, src.scene.n_columns) == (ref.n_rows, ref.n_columns)
    # the truth is the camera itself; the fitted MPC is the stand-in, on the same body
    from explorer.real.csm_sensor import CsmScene

    assert isinstance(src.scene, CsmScene) and src.stand_in is not None
    assert src.stand_in.sensor.frame.body == src.scene.body


# ------------------------------------------------------------------------ address
def test_busy_port_is_an_error_naming_it_and_port_zero_is_free():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        with pytest.raises(InputError, match=f"port {port} on 127.0.0.1 is busy"):
            check_listen_address("127.0.0.1", port)
    check_listen_address("127.0.0.1", 0)


@pytest.mark.parametrize("port", [70000, -1])
def test_port_out_of_range(port):
    with pytest.raises(InputError, match=f"--port {port} is not a port number"):
        check_listen_address("127.0.0.1", port)


def test_host_that_is_not_local_fails_at_once():
    with pytest.raises(InputError, match="not an address of this machine"):
        check_listen_address("192.0.2.1", 0)  # TEST-NET-1: never assigned to a host
    with pytest.raises(InputError, match="--host 'no-such-host.invalid'"):
        check_listen_address("no-such-host.invalid", 0)


def test_rpc_with_its_dem_simulates_points_of_the_rpc_on_the_dem():
    """``--rpc`` with a DEM: the DEM (resampled on the RPC's local frame) is the sensor's terrain; every check point
    is the RPC's own localisation of its pixel (projects back to it) and lies on the DEM, and the learned methods
    measured on them answer with row and column of the RPC."""
    from explorer.methods import create
    from explorer.points import simulate_points

    src = load_source("rpc", str(PHR_2017), dem=str(DEM_2017))
    assert src.info["dem_coverage"]["fraction"] == 1.0 and src.stand_in is None
    terrain = src.scene.terrain
    assert terrain.max_height - terrain.min_height > 50.0  # relief, not a plane
    scps = simulate_points(src.scene, 2000, kind="scp")
    assert len(scps) > 1900
    row, col = src.scene.rpc.projection(*src.scene.frame.enu_to_geodetic(scps.ground))
    assert np.max(np.abs(row - scps.row)) < 1e-6 and np.max(np.abs(col - scps.col)) < 1e-6
    z = terrain.height(scps.ground[:, 0], scps.ground[:, 1])
    assert np.max(np.abs(z - scps.ground[:, 2])) < 0.01  # on the DEM (the straight chord's error is mm)
    scops = simulate_points(src.scene, 100, kind="scop")
    res = create("prm", src.scene).fit(scops).ground_to_image(scps.ground)
    ok = res.valid
    assert ok.mean() > 0.9 and np.max(np.abs(res.col[ok] - col[ok])) < 0.05  # the column from the pairs (X, Y, Z)
