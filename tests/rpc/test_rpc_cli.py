"""CLI handlers called through a parser built here (register(sub))."""

import csv

import numpy as np
import pytest

from explorer.cli import main
from explorer.rpc import read_rpc

from .conftest import RPC_DIR

rpcm = pytest.importorskip("rpcm")


def _run(argv):
    return main(argv)


def test_info(capsys):
    assert _run(["rpc", "info", str(RPC_DIR / "rpc_PLEIADES.xml")]) == 0
    out = capsys.readouterr().out
    assert "format: dimap_v2" in out
    assert "1-based in the file" in out
    assert "(36176, 40000)" in out


def test_project_single_point_matches_rpcm(capsys):
    path = RPC_DIR / "rpc_IKONOS.txt"
    assert (
        _run(["rpc", "project", str(path), "--lon", "-56.17", "--lat", "-34.9", "--h", "20"]) == 0
    )
    out = capsys.readouterr().out
    values = dict(item.split("=") for item in out.split())
    col_ref, row_ref = rpcm.rpc_from_rpc_file(str(path)).projection(-56.17, -34.9, 20.0)
    assert float(values["row"]) == pytest.approx(row_ref, abs=1e-6)
    assert float(values["col"]) == pytest.approx(col_ref, abs=1e-6)


def test_project_and_localize_csv(tmp_path):
    path = RPC_DIR / "rpc_WV2.xml"
    peer = rpcm.rpc_from_rpc_file(str(path))
    lon = np.array([-0.35, -0.3, -0.28])
    lat = np.array([45.62, 45.65, 45.68])
    h = np.array([0.0, 50.0, 120.0])
    src = tmp_path / "in.csv"
    with open(src, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "lon", "lat", "h"])
        for i in range(3):
            w.writerow([i, lon[i], lat[i], h[i]])
    out = tmp_path / "out.csv"
    assert _run(["rpc", "project", str(path), "--points", str(src), "--out", str(out)]) == 0
    rows = list(csv.DictReader(open(out)))
    col_ref, row_ref = peer.projection(lon, lat, h)
    np.testing.assert_allclose([float(r["row"]) for r in rows], row_ref, atol=1e-6)
    np.testing.assert_allclose([float(r["col"]) for r in rows], col_ref, atol=1e-6)
    assert [r["id"] for r in rows] == ["0", "1", "2"]

    loc_in = tmp_path / "img.csv"
    with open(loc_in, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["row", "col", "h"])
        for i in range(3):
            w.writerow([row_ref[i], col_ref[i], h[i]])
    loc_out = tmp_path / "ground.csv"
    assert _run(["rpc", "localize", str(path), "--points", str(loc_in), "--out", str(loc_out)]) == 0
    back = list(csv.DictReader(open(loc_out)))
    np.testing.assert_allclose([float(r["lon"]) for r in back], lon, atol=1e-9)
    np.testing.assert_allclose([float(r["lat"]) for r in back], lat, atol=1e-9)
    assert all(r["converged"] == "True" for r in back)


def test_localize_single_point_gdal_reference(capsys):
    # GDAL test_transformer_5 reference (RPC samp 20, line 10, h 0)
    assert (
        _run(
            ["rpc", "localize", str(RPC_DIR / "rpc.vrt"), "--row", "10", "--col", "20", "--h", "0"]
        )
        == 0
    )
    out = capsys.readouterr().out
    values = dict(item.split("=") for item in out.split())
    assert float(values["lon"]) == pytest.approx(125.64830100509131, abs=1e-6)
    assert float(values["lat"]) == pytest.approx(39.869433991997553, abs=1e-6)


def test_localize_on_dem(capsys):
    from explorer.terrain_io import DEFAULT_ASSETS_DIR, read_geotiff_dem

    dem_path = DEFAULT_ASSETS_DIR / "MNT_P1BP--2018122638935449CP.tif"
    model = read_rpc(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    lon, lat = 2.2, 31.0
    h = read_geotiff_dem(dem_path).height(lon, lat)
    row, col = model.projection(lon, lat, h)
    assert (
        _run(
            [
                "rpc",
                "localize",
                str(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML"),
                "--row",
                repr(float(row)),
                "--col",
                repr(float(col)),
                "--dem",
                str(dem_path),
            ]
        )
        == 0
    )
    values = dict(item.split("=") for item in capsys.readouterr().out.split())
    assert float(values["lon"]) == pytest.approx(lon, abs=1e-7)
    assert float(values["lat"]) == pytest.approx(lat, abs=1e-7)


def test_usage_errors_return_2(capsys):
    assert _run(["rpc", "project", str(RPC_DIR / "rpc_IKONOS.txt")]) == 2
    assert (
        _run(["rpc", "localize", str(RPC_DIR / "rpc_IKONOS.txt"), "--row", "1", "--col", "2"]) == 2
    )
