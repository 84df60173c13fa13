"""One vertical convention for every DEM (issue 25, class 5): ``docs/conventions.md#dem-heights``.

Every command reads ``--dem`` through :func:`explorer.terrain_io.read_dem_above_ellipsoid`: the file's vertical
CRS when it declares one, else ``--dem-datum``, else ellipsoidal heights.  Here the same terrain is written three
ways (EGM96 heights declared by the file's compound CRS, the same heights undeclared, and heights above the
ellipsoid declared by EPSG:4979) and ``rpc localize``, ``scene from-rpc`` and the explorer's ``--dimap`` source
must all put the ground at the same ellipsoidal height.

Independent truth: PROJ's own ``vgridshift`` of the packaged EGM96 grid (pyproj), not the package's
:class:`~explorer.terrain_io.Geoid`, and the RPC's own projection of the localised point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.crs import CRS

from explorer.cli import main
from explorer.errors import InputError
from explorer.terrain_io import DEFAULT_ASSETS_DIR, datum_statement, read_dem_above_ellipsoid

ROOT = Path(__file__).resolve().parents[2]
PHR = ROOT / "tests" / "data" / "rpc" / "PHRDIMAP_P1BP--2018122638935449CP.XML"
DEM_2018 = DEFAULT_ASSETS_DIR / "MNT_P1BP--2018122638935449CP.tif"  # shareloc's "ellipsoide" folder


def geoid_height_proj(lon, lat):
    """EGM96 undulation N (m) by PROJ's vgridshift on the packaged grid (h_ellipsoid = H + N)."""
    from pyproj import Transformer

    pipeline = Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
        f"+step +proj=vgridshift +grids={DEFAULT_ASSETS_DIR / 'egm96_15.gtx'} +multiplier=1 "
        "+step +proj=unitconvert +xy_in=rad +xy_out=deg")
    lon, lat = np.broadcast_arrays(np.asarray(lon, float), np.asarray(lat, float))
    _, _, h = pipeline.transform(lon, lat, np.zeros(lon.shape))
    return np.asarray(h)


def _write(path: Path, heights, transform, crs: str | None) -> Path:
    with rasterio.open(path, "w", driver="GTiff", width=heights.shape[1], height=heights.shape[0], count=1,
                       dtype="float64", crs=CRS.from_string(crs) if crs else None, transform=transform) as ds:
        ds.write(heights, 1)
    return path


@pytest.fixture(scope="module")
def dems(tmp_path_factory):
    """The 2018 Pleiades terrain as EGM96 heights (declared, undeclared) and as ellipsoidal heights (EPSG:4979)."""
    folder = tmp_path_factory.mktemp("dem_datum")
    with rasterio.open(DEM_2018) as src:
        heights = src.read(1).astype(np.float64)
        transform = src.transform
    rows, cols = np.mgrid[0:heights.shape[0], 0:heights.shape[1]]
    lon, lat = transform * (cols + 0.5, rows + 0.5)
    return {
        "egm96_declared": _write(folder / "egm96_declared.tif", heights, transform, "EPSG:4326+5773"),
        "undeclared": _write(folder / "undeclared.tif", heights, transform, "EPSG:4326"),
        "ellipsoid_declared": _write(folder / "ellipsoid_declared.tif", heights + geoid_height_proj(lon, lat),
                                     transform, "EPSG:4979"),
        "egm2008": _write(folder / "egm2008.tif", heights, transform, "EPSG:4326+3855"),
        "feet": _write(folder / "feet.tif", heights, transform, "EPSG:4326+6360"),  # NAVD88 height (ftUS)
        "heights": heights, "transform": transform,
    }


def _raw_height(dems, lon, lat):
    """Bilinear height of the stored grid at (lon, lat) (cell centres), independent of the package."""
    inv = ~dems["transform"]
    fx, fy = inv * (lon, lat)
    j, i = fx - 0.5, fy - 0.5
    j0, i0 = int(np.floor(j)), int(np.floor(i))
    wj, wi = j - j0, i - i0
    g = dems["heights"]
    return ((1 - wi) * (1 - wj) * g[i0, j0] + (1 - wi) * wj * g[i0, j0 + 1] + wi * (1 - wj) * g[i0 + 1, j0]
            + wi * wj * g[i0 + 1, j0 + 1])


def test_the_reader_takes_the_files_declaration_then_the_option_then_ellipsoid(dems):
    lon, lat = np.array([2.15, 2.2, 2.3]), np.array([30.2, 31.0, 30.6])
    truth_egm = np.array([_raw_height(dems, a, b) for a, b in zip(lon, lat, strict=True)]) + geoid_height_proj(lon, lat)
    declared = read_dem_above_ellipsoid(dems["egm96_declared"])
    option = read_dem_above_ellipsoid(dems["undeclared"], datum="egm96")
    ellipsoidal = read_dem_above_ellipsoid(dems["ellipsoid_declared"])
    default = read_dem_above_ellipsoid(dems["undeclared"])
    assert np.abs(declared.height(lon, lat) - truth_egm).max() < 1e-3
    assert np.abs(option.height(lon, lat) - truth_egm).max() < 1e-3
    assert np.abs(ellipsoidal.height(lon, lat) - truth_egm).max() < 2e-3  # bilinear(H + N) vs bilinear(H) + N
    assert np.abs(default.height(lon, lat) - (truth_egm - geoid_height_proj(lon, lat))).max() < 1e-3
    assert "vertical CRS 'EGM96 height'" in datum_statement(declared)
    assert "--dem-datum" in datum_statement(option)
    assert "default" in datum_statement(default) and "ellipsoid" in datum_statement(default)
    assert "ellipsoid" in datum_statement(ellipsoidal) and "4979" not in datum_statement(ellipsoidal)


@pytest.mark.parametrize("name, datum, words", [
    ("egm96_declared", "ellipsoid", ("EGM96 height", "--dem-datum")),
    ("ellipsoid_declared", "egm96", ("ellipsoid", "--dem-datum")),
    ("egm2008", None, ("EGM2008 height", "only ellipsoidal or EGM96")),
    ("feet", None, ("foot", "not metres")),
])
def test_a_datum_that_cannot_be_honoured_is_refused_by_name(dems, name, datum, words):
    with pytest.raises(InputError) as info:
        read_dem_above_ellipsoid(dems[name], datum=datum)
    assert str(dems[name]) in str(info.value) and all(w in str(info.value) for w in words), str(info.value)


def test_an_srtm_tile_is_egm96_by_its_format(tmp_path):
    tile = tmp_path / "N30E002.hgt"
    np.full((1201, 1201), 100, dtype=">i2").tofile(tile)
    dem = read_dem_above_ellipsoid(tile)
    assert dem.height(2.2, 30.5) == pytest.approx(100 + geoid_height_proj(2.2, 30.5), abs=1e-3)
    with pytest.raises(InputError, match="SRTM .hgt tile holds heights above the EGM96 geoid"):
        read_dem_above_ellipsoid(tile, datum="ellipsoid")


def _localize(capsys, dem: Path, *extra: str) -> tuple[float, float, float]:
    assert main(["rpc", "localize", str(PHR), "--row", "3000.5", "--col", "7000.25", "--dem", str(dem),
                 *extra]) == 0
    values = dict(item.split("=") for item in capsys.readouterr().out.split())
    return float(values["lon"]), float(values["lat"]), float(values["h"])


def test_rpc_localize_puts_the_ground_at_the_ellipsoidal_height_whatever_the_files_form(dems, capsys):
    from explorer.rpc import read_rpc

    rpc = read_rpc(PHR)
    points = [_localize(capsys, dems["egm96_declared"]), _localize(capsys, dems["undeclared"], "--dem-datum", "egm96"),
              _localize(capsys, dems["ellipsoid_declared"])]
    for lon, lat, h in points:
        assert h == pytest.approx(_raw_height(dems, lon, lat) + geoid_height_proj(lon, lat)[()], abs=2e-3)
        row, col = rpc.projection(lon, lat, h)
        assert (row, col) == (pytest.approx(3000.5, abs=1e-4), pytest.approx(7000.25, abs=1e-4))
    assert max(abs(p[2] - points[0][2]) for p in points) < 5e-3  # 34 m of geoid apart if one took H as h
    lon, lat, h = _localize(capsys, dems["undeclared"])  # no declaration, no option: ellipsoidal heights
    assert h == pytest.approx(_raw_height(dems, lon, lat), abs=2e-3)


def _terrain_node_errors(scene, dems, *, egm96: bool = True) -> np.ndarray:
    """Ellipsoidal height of (every 25th) valid node of a scene's terrain minus the truth at its lon/lat: the
    stored height H plus the undulation N (``egm96``), or H itself (an ellipsoidal file)."""
    t = scene.terrain
    ny, nx = t.heights.shape
    gx, gy = np.meshgrid(t.x0 + t.dx * np.arange(nx), t.y0 + t.dy * np.arange(ny))
    ok = np.isfinite(t.heights)
    lon, lat, h = scene.frame.enu_to_geodetic(np.stack([gx[ok], gy[ok], t.heights[ok]], axis=1))
    inside = (lon > 2.1) & (lon < 2.33) & (lat > 30.0) & (lat < 31.12)
    raw = np.array([_raw_height(dems, a, b) for a, b in zip(lon[inside][::25], lat[inside][::25], strict=True)])
    n = geoid_height_proj(lon[inside][::25], lat[inside][::25]) if egm96 else 0.0
    return h[inside][::25] - (raw + n)


def test_scene_from_rpc_and_the_explorers_dimap_source_agree_with_rpc_localize(dems, tmp_path, capsys):
    from explorer.real import load_scene
    from explorer.sources import load_source

    out = tmp_path / "scene.json"
    assert main(["scene", "from-rpc", str(PHR), "--dem", str(dems["egm96_declared"]), "--gcps", "30",
                 "--out", str(out)]) == 0
    capsys.readouterr()
    errors = _terrain_node_errors(load_scene(out), dems)
    assert errors.size > 50 and np.abs(errors).max() < 5e-3
    src = load_source("dimap", str(PHR), dem=str(dems["undeclared"]), dem_datum="egm96")
    errors = _terrain_node_errors(src.scene, dems)
    assert errors.size > 50 and np.abs(errors).max() < 5e-3
    assert "EGM96" in src.info["dem_datum"] and "--dem-datum" in src.info["dem_datum"]


def test_the_2018_pleiades_dem_is_ellipsoidal_and_explore_dimap_uses_it_so():
    """shareloc keeps this DEM in its ``ellipsoide`` folder and loads it without a geoid; the file declares no
    vertical datum, so the default (ellipsoidal) applies: the scene's terrain is the file's heights."""
    from explorer.sources import load_source

    with rasterio.open(DEM_2018) as src:
        heights, transform = src.read(1).astype(np.float64), src.transform
    dems = {"heights": heights, "transform": transform}
    source = load_source("dimap", str(PHR), dem=str(DEM_2018))
    errors = _terrain_node_errors(source.scene, dems, egm96=False)
    assert errors.size > 50 and np.abs(errors).max() < 5e-3  # (adding the geoid would put it 34 m too high)
    assert geoid_height_proj(2.2, 30.5)[()] > 30
    assert "default" in source.info["dem_datum"]
