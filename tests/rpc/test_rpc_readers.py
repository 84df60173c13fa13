"""Readers: content dispatch, GDAL's own parse as independent truth, malformed files."""

import shutil
import warnings

import numpy as np
import pytest

from explorer.rpc import (
    RPCFormatError,
    detect_format,
    read_dg_rpb,
    read_gdal_vrt,
    read_rpc,
    read_rpc_from_raster,
)

from .conftest import RPC_DIR, normalisation_grid

rasterio = pytest.importorskip("rasterio")

EXPECTED_FORMATS = {
    "md_dg.RPB": "dg_rpb",
    "md_ge_rgb_0010000_rpc.txt": "rpc00b_txt",
    "md_ov_rpc.txt": "rpc00b_txt",
    "test_rpc.txt": "rpc00b_txt",
    "rpc.vrt": "gdal_vrt",
    "rpc_5395.vrt": "gdal_vrt",
    "rpc_IKONOS.txt": "rpc00b_txt",
    "rpc_PLANET_L1A.txt": "rpc00b_txt",
    "rpc_PLANET_L1B.txt": "rpc00b_txt",
    "rpc_PLEIADES.xml": "dimap_v2",
    "rpc_SPOT6.xml": "dimap_v2",
    "rpc_WV1.xml": "dg_xml",
    "rpc_WV2.xml": "dg_xml",
    "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.geom": "ossim_geom",
    "PHRDIMAP_P1BP--2018122638935449CP.XML": "dimap_v1.4",
    "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML": "dimap_v2",
}


@pytest.mark.parametrize(("name", "fmt"), sorted(EXPECTED_FORMATS.items()))
def test_dispatch_on_content(name, fmt, tmp_path):
    assert detect_format(RPC_DIR / name) == fmt
    # renamed to a neutral extension, the content still decides
    renamed = tmp_path / "renamed.dat"
    shutil.copy(RPC_DIR / name, renamed)
    if fmt != "gdal_vrt":
        assert detect_format(renamed) == fmt
        assert read_rpc(renamed).source_format == fmt


def _gdal_model(rpcs):
    """Our model class filled from GDAL's own parse (rasterio RPC object)."""
    from explorer.rpc import RationalFunctionModel

    d = rpcs.to_dict()
    return RationalFunctionModel(
        row_num=d["line_num_coeff"],
        row_den=d["line_den_coeff"],
        col_num=d["samp_num_coeff"],
        col_den=d["samp_den_coeff"],
        row_offset=d["line_off"],
        col_offset=d["samp_off"],
        lat_offset=d["lat_off"],
        lon_offset=d["long_off"],
        height_offset=d["height_off"],
        row_scale=d["line_scale"],
        col_scale=d["samp_scale"],
        lat_scale=d["lat_scale"],
        lon_scale=d["long_scale"],
        height_scale=d["height_scale"],
    )


@pytest.mark.parametrize("name", ["rpc.vrt", "rpc_5395.vrt"])
def test_vrt_reader_matches_gdal_parse(name):
    ours = read_rpc(RPC_DIR / name)
    with rasterio.open(RPC_DIR / name) as dataset:
        gdal_rpcs = dataset.rpcs
    rpcm = pytest.importorskip("rpcm")
    peer = rpcm.RPCModel(
        {
            k.upper(): (" ".join(map(str, v)) if isinstance(v, list) else v)
            for k, v in gdal_rpcs.to_dict().items()
            if k not in ("err_bias", "err_rand")
        }
    )
    lon, lat, h = normalisation_grid(ours)
    row, col = ours.projection(lon, lat, h)
    col_ref, row_ref = peer.projection(lon, lat, h)
    assert np.max(np.abs(row - row_ref)) < 1e-6
    assert np.max(np.abs(col - col_ref)) < 1e-6


@pytest.mark.parametrize(
    ("name", "sidecar"),
    [("md_dg.RPB", "img.RPB"), ("rpc_IKONOS.txt", "img_RPC.TXT"), ("md_ov_rpc.txt", "img_rpc.txt")],
)
def test_sidecar_reader_matches_gdal_parse(name, sidecar, tmp_path):
    """GDAL reads the same file as the sidecar of a small GeoTIFF; rpcm evaluates it."""
    rpcm = pytest.importorskip("rpcm")
    image = tmp_path / "img.tif"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with rasterio.open(
            image, "w", driver="GTiff", width=4, height=4, count=1, dtype="uint8"
        ) as dst:
            dst.write(np.zeros((1, 4, 4), dtype="uint8"))
    shutil.copy(RPC_DIR / name, tmp_path / sidecar)
    with rasterio.open(image) as dataset:
        gdal_rpcs = dataset.rpcs
    assert gdal_rpcs is not None
    peer = rpcm.RPCModel(
        {
            k.upper(): (" ".join(map(str, v)) if isinstance(v, list) else v)
            for k, v in gdal_rpcs.to_dict().items()
            if k not in ("err_bias", "err_rand")
        }
    )
    ours = read_rpc(RPC_DIR / name)
    lon, lat, h = normalisation_grid(ours)
    row, col = ours.projection(lon, lat, h)
    col_ref, row_ref = peer.projection(lon, lat, h)
    assert np.max(np.abs(row - row_ref)) < 1e-6
    assert np.max(np.abs(col - col_ref)) < 1e-6


def test_geotiff_rpc_tag_round_trip(tmp_path):
    """Write a GeoTIFF carrying the RPC of rpc_IKONOS.txt with rasterio, read it back."""
    from rasterio.rpc import RPC

    source = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    rpcs = RPC(
        height_off=source.height_offset,
        height_scale=source.height_scale,
        lat_off=source.lat_offset,
        lat_scale=source.lat_scale,
        long_off=source.lon_offset,
        long_scale=source.lon_scale,
        line_off=source.row_offset,
        line_scale=source.row_scale,
        samp_off=source.col_offset,
        samp_scale=source.col_scale,
        line_num_coeff=[float(v) for v in source.row_num],
        line_den_coeff=[float(v) for v in source.row_den],
        samp_num_coeff=[float(v) for v in source.col_num],
        samp_den_coeff=[float(v) for v in source.col_den],
    )
    image = tmp_path / "with_rpc.tif"
    with rasterio.open(
        image, "w", driver="GTiff", width=8, height=6, count=1, dtype="uint8", rpcs=rpcs
    ) as dst:
        dst.write(np.zeros((1, 6, 8), dtype="uint8"))
    assert detect_format(image) == "raster"
    back = read_rpc(image)
    assert back.source_format == "raster_rpc"
    assert back.image_size == (6, 8)
    rpcm = pytest.importorskip("rpcm")
    peer = rpcm.rpc_from_rpc_file(str(RPC_DIR / "rpc_IKONOS.txt"))
    lon, lat, h = normalisation_grid(back)
    row, col = back.projection(lon, lat, h)
    col_ref, row_ref = peer.projection(lon, lat, h)
    assert np.max(np.abs(row - row_ref)) < 1e-6
    assert np.max(np.abs(col - col_ref)) < 1e-6


def test_raster_without_rpc_is_rejected(tmp_path):
    image = tmp_path / "plain.tif"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with rasterio.open(
            image, "w", driver="GTiff", width=2, height=2, count=1, dtype="uint8"
        ) as dst:
            dst.write(np.zeros((1, 2, 2), dtype="uint8"))
    with pytest.raises(RPCFormatError, match="plain.tif: raster has no RPC"):
        read_rpc_from_raster(image)


def test_dimap_conventions_and_metadata():
    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    # file: LINE_OFF 18088.5, SAMP_OFF 20000.5 (1-based) -> 0-based
    assert model.row_offset == 18087.5
    assert model.col_offset == 19999.5
    assert model.inverse is not None
    assert model.image_size == (36176, 40000)
    assert model.domain.row_min == 0 and model.domain.col_max == 39999
    wv = read_rpc(RPC_DIR / "rpc_WV2.xml")
    assert wv.image_size == (20289, 28244)


def test_unsupported_xml_is_rejected():
    with pytest.raises(RPCFormatError, match="rpc_unsupported.xml"):
        read_rpc(RPC_DIR / "rpc_unsupported.xml")
    # the explicit VRT reader still reads its GDAL RPC metadata when asked to
    assert read_gdal_vrt(RPC_DIR / "rpc_unsupported.xml").source_format == "gdal_vrt"


def test_missing_coefficient_is_named(tmp_path):
    text = (RPC_DIR / "rpc_IKONOS.txt").read_text()
    lines = [ln for ln in text.splitlines() if not ln.startswith("LINE_NUM_COEFF_12:")]
    broken = tmp_path / "broken_RPC.TXT"
    broken.write_text("\n".join(lines))
    with pytest.raises(RPCFormatError, match="broken_RPC.TXT: missing LINE_NUM_COEFF_12"):
        read_rpc(broken)


def test_truncated_files_are_rejected(tmp_path):
    for name in (
        "rpc_IKONOS.txt",
        "rpc_PLEIADES.xml",
        "md_dg.RPB",
        "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.geom",
        "rpc.vrt",
    ):
        data = (RPC_DIR / name).read_bytes()
        truncated = tmp_path / f"trunc_{name}"
        truncated.write_bytes(data[: len(data) // 2])
        with pytest.raises(RPCFormatError, match=f"trunc_{name}"):
            read_rpc(truncated)


def test_not_an_rpc_and_empty(tmp_path):
    other = tmp_path / "notes.txt"
    other.write_text("hello\nworld\n")
    with pytest.raises(RPCFormatError, match="not a recognised RPC"):
        read_rpc(other)
    empty = tmp_path / "empty_RPC.TXT"
    empty.write_text("")
    with pytest.raises(RPCFormatError, match="is empty"):
        read_rpc(empty)
    with pytest.raises(RPCFormatError, match="not a DigitalGlobe RPB"):
        read_dg_rpb(other)


def test_bad_number_is_named(tmp_path):
    text = (RPC_DIR / "rpc_IKONOS.txt").read_text().replace("LAT_OFF: -34.90300000", "LAT_OFF: abc")
    bad = tmp_path / "bad_RPC.TXT"
    bad.write_text(text)
    with pytest.raises(RPCFormatError, match="LAT_OFF is not a number"):
        read_rpc(bad)


# ------------------------------------------------------------ values validated at read time (issue 18)
def _replace_line(name, key, value, tmp_path, out="bad_RPC.TXT"):
    """A copy of an RPC00B text file with the line of ``key`` holding ``value``."""
    lines = (RPC_DIR / name).read_text().splitlines()
    hits = [i for i, ln in enumerate(lines) if ln.split(":")[0].strip() == key]
    assert len(hits) == 1
    lines[hits[0]] = f"{key}: {value}"
    path = tmp_path / out
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("LINE_OFF", "NaN", "LINE_OFF .* not finite"),
        ("SAMP_OFF", "inf", "SAMP_OFF .* not finite"),
        ("SAMP_SCALE", "0", "SAMP_SCALE .* non-zero"),
        ("LINE_SCALE", "-inf", "LINE_SCALE .* non-zero"),
        ("LAT_OFF", "-134.9", r"LAT_OFF .* -134.9 is outside \[-90, 90\]"),
        ("LAT_SCALE", "120", "LAT_SCALE .* exceeds 90"),
        ("LONG_OFF", "400", r"LONG_OFF .* outside \[-180, 360\]"),
        ("HEIGHT_SCALE", "1e9", "HEIGHT_OFF / HEIGHT_SCALE .* not a ground RPC"),
        ("LINE_NUM_COEFF_7", "1e308", "LINE_NUM_COEFF_7 .* implausibly large"),
        ("SAMP_DEN_COEFF_3", "nan", "SAMP_DEN_COEFF_3 .* not finite"),
        ("LINE_DEN_COEFF_1", "0", "LINE_DEN_COEFF .* vanishes inside the validity domain"),
    ],
)
def test_corrupt_values_are_refused_naming_file_and_field(key, value, message, tmp_path):
    path = _replace_line("test_rpc.txt", key, value, tmp_path)
    with pytest.raises(RPCFormatError, match=f"bad_RPC.TXT: {message}"):
        read_rpc(path)


def test_denominator_changing_sign_inside_the_domain_is_refused(tmp_path):
    # 1 + 2 L: zero at L = -0.5, inside the normalised cube (the file's own denominator is 1 + O(1e-3))
    path = _replace_line("test_rpc.txt", "SAMP_DEN_COEFF_2", "2.0", tmp_path)
    with pytest.raises(RPCFormatError, match="SAMP_DEN_COEFF .* vanishes .* L=-0.67"):
        read_rpc(path)
    # but a denominator with a zero outside the cube (1 + 0.5 L) is a valid model
    ok = read_rpc(_replace_line("test_rpc.txt", "SAMP_DEN_COEFF_2", "0.5", tmp_path, "ok_RPC.TXT"))
    assert ok.col_den[1] == 0.5


def test_corrupt_dimap_validity_is_refused(tmp_path):
    text = (RPC_DIR / "rpc_PLEIADES.xml").read_text()
    start = text.index("<LAT_OFF>") + len("<LAT_OFF>")
    bad = tmp_path / "RPC_bad.XML"
    bad.write_text(text[:start] + "-134.9" + text[text.index("</LAT_OFF>"):])
    with pytest.raises(RPCFormatError, match=r"RPC_bad.XML: LAT_OFF .* outside \[-90, 90\]"):
        read_rpc(bad)


def test_every_real_file_passes_the_validation():
    for name in EXPECTED_FORMATS:
        model = read_rpc(RPC_DIR / name)
        assert max(np.abs(np.r_[model.row_num, model.row_den, model.col_num, model.col_den])) < 15  # O(1)


# ------------------------------------------------------------ validity flags (issue 18)
def test_projection_flags_points_outside_the_validity_domain():
    from explorer.errors import InputError
    from explorer.rpc.model import VALIDITY_MARGIN

    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    lon, lat, h = normalisation_grid(model, 5, 5, 3)
    row, col = model.projection(lon, lat, h)
    row2, col2, valid = model.projection(lon, lat, h, return_valid=True)
    np.testing.assert_array_equal(row2, row)  # same numbers, plus the flags
    np.testing.assert_array_equal(col2, col)
    # the normalisation cube maps inside the file's image box (+ 10 % of the scale): all valid
    inside = model.image_validity(row, col)
    np.testing.assert_array_equal(valid, inside)
    # 100 degrees of longitude away (the row 802,902 / col 286,943 case): a number, flagged
    r_far, c_far, v_far = model.projection(model.lon_offset + 100.0, model.lat_offset, model.height_offset,
                                           return_valid=True)
    assert np.isfinite(r_far) and not v_far
    # just beyond the margin on each normalised axis, and just inside it
    for axis, (off, scale) in enumerate(((model.lon_offset, model.lon_scale), (model.lat_offset, model.lat_scale),
                                         (model.height_offset, model.height_scale))):
        for u, expected in ((1.0 + VALIDITY_MARGIN + 1e-9, False), (1.0 + VALIDITY_MARGIN - 1e-3, True)):
            p = [model.lon_offset, model.lat_offset, model.height_offset]
            p[axis] = off + u * abs(scale)
            assert bool(model.ground_validity(*p)) is expected
    # latitude 200 and infinite inputs are errors, naming the input (numba and numpy paths)
    for backend in ("numba", "numpy"):
        with pytest.raises(InputError, match="lat must be within"):
            model.projection(model.lon_offset, 200.0, 0.0, backend=backend)
        with pytest.raises(InputError, match="lon contains infinite"):
            model.projection(np.inf, model.lat_offset, 0.0, backend=backend)
        with pytest.raises(InputError, match="h contains NaN"):
            model.projection(model.lon_offset, model.lat_offset, np.nan, backend=backend)


def test_localization_far_outside_is_not_converged_and_flags_are_returned():
    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    rows, cols = model.image_size
    row = np.array([-1e6, 0.0, rows - 1.0, rows - 1.0 + 0.5 * model.row_scale, 1e9])
    col = np.array([cols / 2, 0.0, cols - 1.0, cols / 2, cols / 2])
    lon, lat, ok, valid = model.localization(row, col, model.height_offset, return_valid=True)
    # row -1e6 and 1e9: Newton lands somewhere far away; never reported converged
    np.testing.assert_array_equal(ok, [False, True, True, True, False])
    assert np.isnan(lon[0]) and np.isnan(lat[4])
    # the image corners are valid; half a scale beyond the last row is converged but outside the domain
    np.testing.assert_array_equal(valid, [False, True, True, False, False])
    # the corners round-trip through the projection (independent direction)
    r2, c2 = model.projection(lon[1:3], lat[1:3], model.height_offset)
    np.testing.assert_allclose(r2, row[1:3], atol=1e-6)
    np.testing.assert_allclose(c2, col[1:3], atol=1e-6)
    # the default return API is unchanged
    assert len(model.localization(row, col, model.height_offset)) == 3


def test_cli_project_prints_the_validity_flag(capsys, tmp_path):
    from explorer.cli import main

    path = RPC_DIR / "rpc_IKONOS.txt"
    model = read_rpc(path)
    assert main(["rpc", "project", str(path), "--lon", "-56.17", "--lat", "-34.9", "--h", "20"]) == 0
    out = capsys.readouterr()
    assert out.out.strip().endswith("valid=True") and out.err == ""
    # 100 degrees of longitude away: the extrapolated numbers are printed with valid=False and one warning line
    assert main(["rpc", "project", str(path), "--lon", "43.83", "--lat", "-34.9", "--h", "20"]) == 0
    out = capsys.readouterr()
    values = dict(item.split("=") for item in out.out.split())
    r_far, c_far = model.projection(43.83, -34.9, 20.0)
    assert float(values["row"]) == pytest.approx(r_far) and values["valid"] == "False"
    assert out.err.count("\n") == 1 and "outside the RPC's validity domain" in out.err
    src = tmp_path / "in.csv"
    src.write_text("lon,lat,h\n-56.17,-34.9,20\n43.83,-34.9,20\n")
    assert main(["rpc", "project", str(path), "--points", str(src), "--out", str(tmp_path / "out.csv")]) == 0
    lines = (tmp_path / "out.csv").read_text().splitlines()
    assert lines[0].endswith(",valid") and lines[1].endswith(",True") and lines[2].endswith(",False")


def _with_ground_box(tmp_path, name, box):
    """A copy of the PLEIADES DIMAP v2 file with FIRST_LON, FIRST_LAT, LAST_LON, LAST_LAT replaced."""
    text = (RPC_DIR / "rpc_PLEIADES.xml").read_text()
    for key, value in zip(("FIRST_LON", "FIRST_LAT", "LAST_LON", "LAST_LAT"), box, strict=True):
        start = text.index(f"<{key}>") + len(f"<{key}>")
        text = text[:start] + repr(float(value)) + text[text.index(f"</{key}>"):]
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_declared_ground_box_that_misses_the_centre_is_read_as_stated(tmp_path):
    """rpcm's rpc_SPOT6.xml writes latitudes in FIRST_LON/LAST_LON and longitudes in FIRST_LAT/LAST_LAT: as
    declared, no ground point of the image is valid (the explorer drew 0 check points).  The box is read
    swapped, with a note; a box that contains the centre neither way is dropped, with a note."""
    spot = read_rpc(RPC_DIR / "rpc_SPOT6.xml")
    d = spot.domain
    assert d.lon_min <= spot.lon_offset <= d.lon_max and d.lat_min <= spot.lat_offset <= d.lat_max
    assert (d.lon_min, d.lon_max, d.lat_min, d.lat_max) == (-72.4395036093, -72.0984267043, 18.3932164171,
                                                            18.7570975666)  # the file's numbers, swapped
    assert "swapped" in spot.metadata["validity_note"] and "LONG_OFF -72.269" in spot.metadata["validity_note"]
    lon, lat, h = normalisation_grid(spot, 5, 5, 3)
    inside = spot.in_domain(lon, lat, h)
    assert inside.sum() >= 27  # the inner 3 x 3 x 3 nodes of the normalisation cube lie in the (swapped) box
    _, _, valid = spot.projection(lon[inside], lat[inside], h[inside], return_valid=True)
    assert valid.all()
    # a consistent file: no note, the declared box kept
    ple = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    assert "validity_note" not in ple.metadata
    box = (ple.domain.lon_min, ple.domain.lat_min, ple.domain.lon_max, ple.domain.lat_max)
    # the same box written swapped is read back as the original
    swapped = read_rpc(_with_ground_box(tmp_path, "RPC_swapped.XML", (box[1], box[0], box[3], box[2])))
    assert (swapped.domain.lon_min, swapped.domain.lat_min, swapped.domain.lon_max, swapped.domain.lat_max) == box
    # a box 10 degrees away is not the model's: dropped, the domain is offset +- scale
    away = read_rpc(_with_ground_box(tmp_path, "RPC_away.XML", (box[0] + 10, box[1], box[2] + 10, box[3])))
    assert "not used" in away.metadata["validity_note"]
    assert away.domain.lon_min == pytest.approx(away.lon_offset - abs(away.lon_scale))
    assert away.domain.lat_max == pytest.approx(away.lat_offset + abs(away.lat_scale))
