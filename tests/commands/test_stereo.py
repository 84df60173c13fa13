"""``pushbroom stereo grids`` and ``stereo triangulate`` on the public Pleiades pair: points recovered from
rpcm's projections, grid files in OTB's convention, grids on a DEM whose nodes meet at the DEM's height."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from explorer import read_rpc
from explorer.cli import main
from explorer.stereo.sensors import as_sensor, localise
from explorer.terrain_io import read_geotiff_dem
from tests.stereo.pairs import PHR_PAIRS, rpcm_pair

LEFT, RIGHT = (str(p) for p in PHR_PAIRS["xml"])


def test_triangulate_csv(tmp_path, capsys):
    peer_l, peer_r = rpcm_pair()
    rng = np.random.default_rng(7)
    lon, lat, h = rng.uniform(7.1, 7.25, 50), rng.uniform(43.64, 43.71, 50), rng.uniform(100, 1000, 50)
    lcol, lrow = peer_l.projection(lon, lat, h)
    rcol, rrow = peer_r.projection(lon, lat, h)
    matches = tmp_path / "matches.csv"
    with open(matches, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "left_row", "left_col", "right_row", "right_col"])
        for i in range(50):
            w.writerow([i, *(repr(float(v[i])) for v in (lrow, lcol, rrow, rcol))])
        w.writerow([50, -10.0, 5.0, 5.0, 5.0])  # outside the left image: flagged, not extrapolated
    out = tmp_path / "points.csv"
    assert main(["stereo", "triangulate", LEFT, RIGHT, "--matches", str(matches), "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert "1 match(es) flagged" in captured.err and "outside left image 1" in captured.err
    with open(out, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["id"] for r in rows] == [str(i) for i in range(51)]
    got = np.array([[float(r["lon"]), float(r["lat"]), float(r["height"])] for r in rows[:50]])
    assert np.max(np.abs(got[:, 2] - h)) < 1e-3
    assert np.max(np.abs(got[:, 0] - lon)) < 1e-8 and np.max(np.abs(got[:, 1] - lat)) < 1e-8
    assert all(r["valid"] == "True" for r in rows[:50])
    assert rows[50]["valid"] == "False" and rows[50]["height"] == "nan" and int(rows[50]["flags"]) & 1


def test_grids_at_a_height(tmp_path, capsys):
    assert main(["stereo", "grids", LEFT, RIGHT, "--height", "300", "--step", "900", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "epipolar image 45520 x 35595" in text
    summary = json.loads((tmp_path / "grids.json").read_text())
    assert summary["grid_size"] == {"rows": 52, "columns": 41}
    with rasterio.open(tmp_path / "right_epipolar_grid.tif") as ds:
        assert ds.count == 3 and ds.transform.a == 900


def _synthetic_dem(path):
    """A lon/lat GeoTIFF over the pair: a 400 m plane tilted by 300 m over 0.3 degrees of longitude plus a hill."""
    lon = np.arange(6.95, 7.40, 0.002)
    lat = np.arange(43.80, 43.55, -0.002)
    lo, la = np.meshgrid(lon + 0.001, lat - 0.001)
    z = 400.0 + 1000.0 * (lo - 7.1) + 250.0 * np.exp(-((lo - 7.18) ** 2 + (la - 43.68) ** 2) / 0.02**2)
    with rasterio.open(path, "w", driver="GTiff", width=lon.size, height=lat.size, count=1, dtype="float64",
                       crs="EPSG:4326", transform=from_origin(6.95, 43.80, 0.002, 0.002)) as ds:
        ds.write(z, 1)


@pytest.mark.slow
def test_grids_on_a_dem_meet_at_the_dem(tmp_path):
    dem_path = tmp_path / "dem.tif"
    _synthetic_dem(dem_path)
    out = tmp_path / "grids"
    assert main(["stereo", "grids", LEFT, RIGHT, "--dem", str(dem_path), "--step", "1500", "--out", str(out)]) == 0
    with rasterio.open(out / "left_epipolar_grid.tif") as ds:
        dx_l, dy_l, h_l = ds.read(1), ds.read(2), ds.read(3)
        step = ds.transform.a
    with rasterio.open(out / "right_epipolar_grid.tif") as ds:
        dx_r, dy_r = ds.read(1), ds.read(2)
    i, j = np.meshgrid(np.arange(h_l.shape[0]), np.arange(h_l.shape[1]), indexing="ij")
    lrow, lcol = i * step + dy_l - 0.5, j * step + dx_l - 0.5
    rrow, rcol = i * step + dy_r - 0.5, j * step + dx_r - 0.5
    ok = np.isfinite(h_l)
    assert ok.mean() > 0.5
    left, right = (as_sensor(read_rpc(p)) for p in (LEFT, RIGHT))
    a, ok_a = localise(left, lrow[ok], lcol[ok], h_l[ok])
    b, ok_b = localise(right, rrow[ok], rcol[ok], h_l[ok])
    assert ok_a.all() and ok_b.all()
    assert np.max(np.linalg.norm(a - b, axis=1)) < 0.01
    # the node's height is the DEM's (bilinear between cell centres) under its ground point
    from explorer.geometry.frames import ecef_to_geodetic

    lon, lat, _ = ecef_to_geodetic(a)
    dem = read_geotiff_dem(dem_path)
    np.testing.assert_allclose(dem.height(lon, lat), h_l[ok], atol=1e-3)


def test_grids_refuse_height_and_dem_together(tmp_path, capsys):
    dem_path = tmp_path / "dem.tif"
    _synthetic_dem(dem_path)
    code = main(["stereo", "grids", LEFT, RIGHT, "--height", "1", "--dem", str(dem_path), "--out", str(tmp_path)])
    assert code == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_hostile_pair_and_outputs(tmp_path, capsys):
    ikonos = str(PHR_PAIRS["xml"][0].parent / "rpc_IKONOS.txt")
    assert main(["stereo", "grids", LEFT, ikonos, "--height", "300", "--out", str(tmp_path / "g")]) == 2
    assert "do not overlap" in capsys.readouterr().err
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    assert main(["stereo", "grids", LEFT, RIGHT, "--height", "300", "--step", "900", "--out", str(a_file)]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    assert main(["stereo", "grids", LEFT, str(a_file), "--height", "300", "--out", str(tmp_path / "g")]) == 2
    assert "not a recognised RPC format" in capsys.readouterr().err
    matches = tmp_path / "m.csv"
    matches.write_text("left_row,left_col\n1,2\n")
    assert main(["stereo", "triangulate", LEFT, RIGHT, "--matches", str(matches), "--out",
                 str(tmp_path / "p.csv")]) == 2
    assert "missing column(s) right_row, right_col" in capsys.readouterr().err
    assert not (tmp_path / "p.csv").exists()
