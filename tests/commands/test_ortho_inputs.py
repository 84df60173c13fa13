"""``pushbroom ortho`` on the valid and hostile inputs of issue 25 (classes 1, 4, 5 and 6): a coarse output
grid works, a learned method is fitted on SCOPs from the scene, an impossible height or an output without a
single seen pixel is one line naming the option and leaves no file, and a DEM tile is read with one height
convention by ``ortho`` and ``rpc localize``.

Truths: the known ground pattern of ``--synthetic`` (geolocation), the RPC's own localisation, the SRTM tile's
stored heights plus the EGM96 undulation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from explorer.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
PHR = ROOT / "tests" / "data" / "rpc" / "PHRDIMAP_P1BP--2018122638935449CP.XML"


def _report(text: str) -> dict:
    return json.loads(text[text.index("{"):text.rindex("}") + 1])


def _one_line_error(capsys, *words: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    lines = [line for line in err if "ortho blocks" not in line and "compiling" not in line]
    assert len(lines) == 1, err
    assert "Traceback" not in lines[0] and all(w in lines[0] for w in words), lines[0]
    return lines[0]


def test_a_coarse_output_grid_is_a_normal_request(tmp_path, capsys):
    """WSU at 20 m: 116 x 114 output pixels, too few 64-pixel tiles for the geolocation check (once a traceback
    after the GeoTIFF was written); the check takes smaller tiles and the pattern is found in place."""
    out = tmp_path / "o.tif"
    assert main(["ortho", "--preset", "WSU", "--synthetic", "--gsd", "20", "--out", str(out)]) == 0
    geo = _report(capsys.readouterr().out)["geolocation"]
    assert geo["n_tiles"] >= 1 and geo["tile_px"] < 64
    assert geo["max_px"] < 0.01
    assert out.is_file()


def test_a_learned_method_is_fitted_on_scops_simulated_from_the_scene(tmp_path, capsys):
    out = tmp_path / "lrm.tif"
    assert main(["ortho", "--preset", "SCB", "--synthetic", "--gsd", "30", "--chunk", "64", "--method", "lrm",
                 "--scops", "50", "--out", str(out)]) == 0
    geo = _report(capsys.readouterr().out)["geolocation"]
    assert geo["n_tiles"] >= 4 and geo["max_px"] < 0.1  # an affine model: sub-pixel at this GSD


def test_a_search_method_on_an_rpc_is_one_line_naming_the_option(tmp_path, capsys):
    out = tmp_path / "o.tif"
    assert main(["ortho", "--rpc", str(PHR), "--synthetic", "--rpc-shape", "200x200", "--gsd", "5",
                 "--method", "nr", "--out", str(out)]) == 2
    _one_line_error(capsys, "--method")
    assert not out.exists()


@pytest.mark.parametrize("height", ["1000000", "-7000000"])
def test_a_height_the_lines_of_sight_never_reach_is_one_line_naming_height(tmp_path, capsys, height):
    img = tmp_path / "img.npy"
    np.lib.format.open_memmap(img, mode="w+", dtype=np.uint8, shape=(3996, 4015)).flush()  # WSU's size
    out = tmp_path / "o.tif"
    assert main(["ortho", "--preset", "WSU", "--image", str(img), "--height", height, "--gsd", "20",
                 "--out", str(out)]) == 2
    _one_line_error(capsys, "--height")
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["img.npy"]


def test_a_height_outside_the_rpcs_domain_is_one_line_naming_height(tmp_path, capsys):
    out = tmp_path / "o.tif"
    assert main(["ortho", "--rpc", str(PHR), "--synthetic", "--rpc-shape", "200x200", "--gsd", "5",
                 "--height", "1000000", "--out", str(out)]) == 2
    _one_line_error(capsys, "--height", "height range")
    assert not out.exists()


def test_an_output_without_one_seen_pixel_is_refused_and_not_written(tmp_path, capsys, monkeypatch):
    from explorer import ortho

    def nothing_seen(self, lon, lat):
        nan = np.full(lon.shape, np.nan)
        return nan, nan, np.zeros(lon.shape, bool)

    monkeypatch.setattr(ortho.OrthoGeometry, "locate", nothing_seen)
    out = tmp_path / "o.tif"
    assert main(["ortho", "--preset", "SCB", "--synthetic", "--gsd", "60", "--height", "500",
                 "--out", str(out)]) == 2
    _one_line_error(capsys, "--height 500", "no output pixel")
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_failure_after_the_blocks_leaves_no_geotiff_under_the_final_name(tmp_path, capsys, monkeypatch):
    from explorer import ortho

    def broken(*args, **kwargs):
        raise RuntimeError("the measurement broke")

    monkeypatch.setattr(ortho, "measure_geolocation", broken)
    out = tmp_path / "o.tif"
    assert main(["ortho", "--preset", "SCB", "--synthetic", "--gsd", "60", "--out", str(out)]) != 0
    capsys.readouterr()
    assert not out.exists() and list(tmp_path.iterdir()) == []


def _srtm_tile(folder: Path, height_m: int) -> Path:
    """N31E002.hgt (3 arc-second, big-endian int16) of one height: the tile under the 2018 Pleiades image."""
    path = folder / "N31E002.hgt"
    np.full((1201, 1201), height_m, dtype=">i2").tofile(path)
    return path


def test_ortho_and_rpc_localize_read_an_srtm_tile_with_one_height_convention(tmp_path, capsys):
    """SRTM heights are above the EGM96 geoid: both commands add the undulation N (34.5 m here)."""
    from explorer.commands.ortho import build_ortho_job
    from explorer.terrain_io import Geoid

    tile = _srtm_tile(tmp_path, 500)
    assert main(["rpc", "localize", str(PHR), "--row", "1000", "--col", "20000", "--dem", str(tile)]) == 0
    record = dict(item.split("=") for item in capsys.readouterr().out.split())  # lon=.. lat=.. h=.. converged=..
    assert record["converged"] == "True"
    lon, lat, h = float(record["lon"]), float(record["lat"]), float(record["h"])
    undulation = float(Geoid.egm96().geoid_height(lon, lat))
    assert abs(undulation) > 10.0
    assert h == pytest.approx(500.0 + undulation, abs=1e-3)
    args = build_parser().parse_args(["ortho", "--rpc", str(PHR), "--dem", str(tile), "--synthetic",
                                      "--rpc-shape", "400x400", "--gsd", "5", "--out", str(tmp_path / "o.tif")])
    geometry = build_ortho_job(args, tmp_path)[0]
    ortho_h = geometry.surface.heights(geometry.sensor, np.array([lon]), np.array([lat]))[0]
    assert ortho_h == pytest.approx(h, abs=1e-3)


def test_ortho_of_a_rigorous_dimap_model_projects_with_the_model_itself(tmp_path, capsys):
    """``--dimap``: the sensor comes through the one file loader; the output pixels' image positions are the
    rigorous model's own ground to image (its bracketing solver, independent of the methods)."""
    from explorer.commands.ortho import build_ortho_job

    img = tmp_path / "img.npy"
    np.lib.format.open_memmap(img, mode="w+", dtype=np.uint8, shape=(38248, 40000)).flush()  # sparse file
    out = tmp_path / "o.tif"
    argv = ["ortho", "--dimap", str(PHR), "--image", str(img), "--gsd", "400", "--out", str(out)]
    geometry = build_ortho_job(build_parser().parse_args(argv), tmp_path)[0]
    scene = geometry.sensor.scene
    assert type(scene).__name__ == "RigorousLineScanScene"
    rng = np.random.default_rng(2)
    lon0, lat0 = scene.frame.lon0_deg, scene.frame.lat0_deg
    lon, lat = lon0 + rng.uniform(-0.05, 0.05, 40), lat0 + rng.uniform(-0.05, 0.05, 40)
    row, col, valid = geometry.locate(lon, lat)
    assert valid.all()
    r_ref, c_ref = scene.ground_to_image(geometry.surface.ground(geometry.sensor, lon, lat))
    assert np.max(np.hypot(row - r_ref, col - c_ref)) < 1e-6
    capsys.readouterr()
    assert main(argv) == 0
    assert _report(capsys.readouterr().out)["valid_pixels"] > 1000


def test_an_image_of_another_body_is_refused_naming_it(tmp_path, capsys):
    isd = ROOT / "tests" / "data" / "usgscsm" / "ctxLineScan.json"
    out = tmp_path / "o.tif"
    assert main(["ortho", "--isd", str(isd), "--synthetic", "--gsd", "100", "--out", str(out)]) == 2
    _one_line_error(capsys, "--isd", "Mars")
    assert not out.exists()


def test_a_scenes_dem_becomes_its_terrain_and_one_missing_the_footprint_is_refused(tmp_path, capsys):
    """WSU (San Diego) on an SRTM tile of one height: the synthetic source and the orthoimage see the same ground
    (geolocation against the known pattern), the tile's heights above EGM96 (the undulation is about -35 m
    there); the Pleiades tile (Algeria) misses the footprint: one line naming --dem."""
    from explorer.commands.ortho import build_ortho_job
    from explorer.terrain_io import Geoid

    here = tmp_path / "N32W118.hgt"
    np.full((1201, 1201), 200, dtype=">i2").tofile(here)
    out = tmp_path / "o.tif"
    argv = ["ortho", "--preset", "WSU", "--dem", str(here), "--synthetic", "--gsd", "50", "--out", str(out)]
    geometry = build_ortho_job(build_parser().parse_args(argv), tmp_path)[0]
    frame = geometry.sensor.frame
    lon, lat = np.array([frame.lon0_deg]), np.array([frame.lat0_deg])
    h = geometry.surface.heights(geometry.sensor, lon, lat)[0]
    assert h == pytest.approx(200.0 + float(Geoid.egm96().geoid_height(lon, lat)[0]), abs=0.01)
    assert main(argv) == 0
    geo = _report(capsys.readouterr().out)["geolocation"]
    assert geo["max_px"] < 0.01
    elsewhere = _srtm_tile(tmp_path, 500)
    out2 = tmp_path / "o2.tif"
    assert main(["ortho", "--preset", "WSU", "--dem", str(elsewhere), "--synthetic", "--gsd", "50",
                 "--out", str(out2)]) == 2
    _one_line_error(capsys, "--dem", "does not cover")
    assert not out2.exists()


def test_a_learned_method_on_an_rpc_is_fitted_on_the_rpc_itself(tmp_path, capsys):
    """Issue 23: a learned method needs only ground / image pairs, so ``ortho --rpc --method`` fits it on SCOPs of
    the RPC itself (3 height layers; its column from the pairs).  Truth: the synthetic pattern rendered through the
    RPC's own localisation; the geolocation the report measures is the method's ground to image against it
    (measured: lrm 0.0013 px, the RPC itself 0.00076 px; a cubic-in-height column model gave 0.79 px)."""
    out = tmp_path / "o.tif"
    assert main(["ortho", "--rpc", str(PHR), "--synthetic", "--rpc-shape", "600x600", "--gsd", "2",
                 "--method", "lrm", "--out", str(out)]) == 0
    geo = _report(capsys.readouterr().out)["geolocation"]
    assert out.exists() and geo["n_tiles"] >= 4 and geo["max_px"] < 0.01
