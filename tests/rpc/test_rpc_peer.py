"""Agreement with the peer library rpcm and with the upstream projects' reference values.

Reference values: tests/data/rpc/PROVENANCE.md and the shared REFERENCE_VALUES.md (GDAL
autotest/gcore/transformer.py, CNES shareloc tests/geomodels/test_rpc.py). shareloc's pixel
convention is the pixel corner: shareloc (row, col) = ours (0-based centre) + 0.5.
"""

import numpy as np
import pytest

from explorer.rpc import read_dimap_v1, read_rpc

from .conftest import RPC_DIR, RPCM_READABLE, normalisation_grid

rpcm = pytest.importorskip("rpcm")


@pytest.mark.parametrize("name", RPCM_READABLE)
def test_projection_matches_rpcm_on_domain_grid(name):
    path = RPC_DIR / name
    ours = read_rpc(path)
    peer = rpcm.rpc_from_rpc_file(str(path))
    lon, lat, h = normalisation_grid(ours)
    row, col = ours.projection(lon, lat, h)
    col_ref, row_ref = peer.projection(lon, lat, h)
    assert np.max(np.abs(row - row_ref)) < 1e-6
    assert np.max(np.abs(col - col_ref)) < 1e-6


@pytest.mark.parametrize("name", RPCM_READABLE)
def test_localization_round_trip_and_rpcm(name):
    path = RPC_DIR / name
    ours = read_rpc(path)
    peer = rpcm.rpc_from_rpc_file(str(path))
    lon, lat, h = normalisation_grid(ours, 7, 7, 3)
    col_ref, row_ref = peer.projection(lon, lat, h)  # independent image points
    lon_est, lat_est, ok = ours.localization(row_ref, col_ref, h)
    assert ok.all()
    assert np.max(np.abs(lon_est - lon)) < 1e-9
    assert np.max(np.abs(lat_est - lat)) < 1e-9


@pytest.mark.parametrize(
    "name",
    ["rpc_PLEIADES.xml", "rpc_SPOT6.xml", "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML"],
)
def test_dimap_inverse_model_matches_rpcm(name):
    """The file's image->ground functions evaluated by rpcm and by us (same 0-based shift)."""
    path = RPC_DIR / name
    ours = read_rpc(path)
    peer = rpcm.rpc_from_rpc_file(str(path))
    rows = np.linspace(ours.domain.row_min, ours.domain.row_max, 11)
    cols = np.linspace(ours.domain.col_min, ours.domain.col_max, 11)
    r, c = np.meshgrid(rows, cols)
    h = np.full(r.shape, ours.height_offset)
    lon, lat = ours.inverse_localization(r, c, h)
    lon_ref, lat_ref = peer.localization(c, r, h)
    assert np.max(np.abs(lon - lon_ref)) < 1e-12
    assert np.max(np.abs(lat - lat_ref)) < 1e-12


# ----------------------------------------------------------- upstream reference values
def test_shareloc_dimap_v2_reference_projection():
    # shareloc test_rpc_dimap_v2: col 100.5, row 200.5 (pixel corner) at tol 1e-2 px
    for name in (
        "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML",
        "PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.geom",
    ):
        model = read_rpc(RPC_DIR / name)
        row, col = model.projection(7.048662660737769592, 43.72774839443545858, 0.0)
        assert row + 0.5 == pytest.approx(200.5, abs=1e-2)
        assert col + 0.5 == pytest.approx(100.5, abs=1e-2)


def test_shareloc_ossim_kwl_reference_projection():
    model = read_rpc(RPC_DIR / "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.geom")
    row, col = model.projection(
        7.11526088296757386331137240632, 43.684281179313565246502548689, 850.0
    )
    assert col + 0.5 == pytest.approx(10121.5657, abs=1e-2)
    assert row + 0.5 == pytest.approx(10236.4310, abs=1e-2)


@pytest.mark.parametrize("scene", ["178608", "178609"])
def test_ossim_geom_matches_rpcm_reading_the_dimap_twin(scene):
    """The .geom (0-based) and the DIMAP RPC_*.XML (1-based) of one scene are the same model."""
    stem = {
        "178608": "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001",
        "178609": "PHR1B_P_201709281038393_SEN_PRG_FC_178609-001",
    }[scene]
    ours = read_rpc(RPC_DIR / f"{stem}.geom")
    peer = rpcm.rpc_from_rpc_file(str(RPC_DIR / f"RPC_{stem}.XML"))
    lon, lat, h = normalisation_grid(ours)
    row, col = ours.projection(lon, lat, h)
    col_ref, row_ref = peer.projection(lon, lat, h)
    # the two files print the coefficients with different digits: agreement to 1e-6 px
    assert np.max(np.abs(row - row_ref)) < 1e-6
    assert np.max(np.abs(col - col_ref)) < 1e-6


def test_gdal_rpc_vrt_localization_reference():
    # GDAL test_transformer_5: GDAL pixel/line (20.5, 10.5) = RPC samp 20, line 10
    model = read_rpc(RPC_DIR / "rpc.vrt")
    lon, lat, ok = model.localization([10.0, 10.0], [20.0, 20.0], [0.0, 30.0])
    assert ok.all()
    assert lon[0] == pytest.approx(125.64830100509131, abs=1e-6)
    assert lat[0] == pytest.approx(39.869433991997553, abs=1e-6)
    assert lon[1] == pytest.approx(125.64828521533849, abs=1e-6)
    assert lat[1] == pytest.approx(39.869345204440144, abs=1e-6)


def test_gdal_rpc_5395_converges_to_reference():
    # GDAL test_transformer_6 (LAT/LONG_SCALE = 1, a convergence bug report)
    model = read_rpc(RPC_DIR / "rpc_5395.vrt")
    lon, lat, ok = model.localization(0.0, 0.0, 0.0)
    assert ok
    assert lon == pytest.approx(28.26163232, abs=1e-4)
    assert lat == pytest.approx(-27.79853245, abs=1e-4)


def test_shareloc_phrdimap_altitude_range():
    # shareloc test_rpc_minmax: get_alt_min_max = offset -+ scale / 2 -> exactly 532.5, 617.5
    model = read_dimap_v1(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    assert model.height_range(0.5) == (532.5, 617.5)


def test_phrdimap_direct_model_round_trip_shareloc_tolerance():
    """shareloc test_rpc_phrdimap: direct model (vendor image->ground) then projection
    returns to (row 200, col 600) within 2e-2 px (pixel corner in shareloc = ours + 0.5)."""
    model = read_rpc(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    row_sl, col_sl, alt = 200.0, 600.0, 125.0
    lon, lat = model.inverse_localization(row_sl - 0.5, col_sl - 0.5, alt)
    row, col = model.projection(lon, lat, alt)
    assert row + 0.5 == pytest.approx(row_sl, abs=2e-2)
    assert col + 0.5 == pytest.approx(col_sl, abs=2e-2)


def test_phrdimap_projection_matches_rpcm_evaluation():
    """rpcm cannot read DIMAP v1.4; its evaluator on the same numbers checks our evaluation,
    and the vendor's inverse model (evaluated by rpcm) checks the 1-based shift."""
    model = read_rpc(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    d = {
        "LINE_OFF": model.row_offset,
        "SAMP_OFF": model.col_offset,
        "LAT_OFF": model.lat_offset,
        "LONG_OFF": model.lon_offset,
        "HEIGHT_OFF": model.height_offset,
        "LINE_SCALE": model.row_scale,
        "SAMP_SCALE": model.col_scale,
        "LAT_SCALE": model.lat_scale,
        "LONG_SCALE": model.lon_scale,
        "HEIGHT_SCALE": model.height_scale,
        "LINE_NUM_COEFF": " ".join(repr(float(v)) for v in model.row_num),
        "LINE_DEN_COEFF": " ".join(repr(float(v)) for v in model.row_den),
        "SAMP_NUM_COEFF": " ".join(repr(float(v)) for v in model.col_num),
        "SAMP_DEN_COEFF": " ".join(repr(float(v)) for v in model.col_den),
        "LON_NUM_COEFF": " ".join(repr(float(v)) for v in model.inverse.lon_num),
        "LON_DEN_COEFF": " ".join(repr(float(v)) for v in model.inverse.lon_den),
        "LAT_NUM_COEFF": " ".join(repr(float(v)) for v in model.inverse.lat_num),
        "LAT_DEN_COEFF": " ".join(repr(float(v)) for v in model.inverse.lat_den),
    }
    peer = rpcm.RPCModel(d)
    lon, lat, h = normalisation_grid(model)
    row, col = model.projection(lon, lat, h)
    col_ref, row_ref = peer.projection(lon, lat, h)
    assert np.max(np.abs(row - row_ref)) < 1e-6
    assert np.max(np.abs(col - col_ref)) < 1e-6
    # vendor inverse vs our exact inverse: within the file's MODEL_PRECISION scale (pixels)
    r = np.linspace(0, 38247, 7)
    c = np.linspace(0, 39999, 7)
    rr, cc = np.meshgrid(r, c)
    hh = np.full(rr.shape, 575.0)
    lon_v, lat_v = peer.localization(cc, rr, hh)
    row_b, col_b = model.projection(lon_v, lat_v, hh)
    assert np.max(np.abs(row_b - rr)) < 0.05
    assert np.max(np.abs(col_b - cc)) < 0.05
