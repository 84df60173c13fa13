"""Model behaviour: input checks, convergence flags, domain, DEM intersection (closed forms)."""

import numpy as np
import pytest

from explorer.rpc import ConvergenceError, RationalFunctionModel, read_rpc
from explorer.rpc.dem import localization_on_dem
from explorer.rpc.model import RPC00B_TERMS, evaluate_rpc00b_polynomial, rpc00b_monomials

from .conftest import RPC_DIR


def _affine_model(row_scale=1000.0, col_scale=2000.0):
    """row = 500 + 1000 P', col = 1000 + 2000 L' (L', P' normalised lon, lat): closed form."""
    num_r = np.zeros(20)
    num_r[2] = 1.0
    num_c = np.zeros(20)
    num_c[1] = 1.0
    den = np.zeros(20)
    den[0] = 1.0
    return RationalFunctionModel(
        row_num=num_r,
        row_den=den,
        col_num=num_c,
        col_den=den,
        row_offset=500.0,
        col_offset=1000.0,
        lat_offset=45.0,
        lon_offset=5.0,
        height_offset=0.0,
        row_scale=row_scale,
        col_scale=col_scale,
        lat_scale=0.1,
        lon_scale=0.2,
        height_scale=500.0,
    )


def test_polynomial_matches_monomials_term_by_term():
    rng = np.random.default_rng(1)
    x, y, z = rng.uniform(-1, 1, (3, 50))
    mono = rpc00b_monomials(x, y, z)
    for k in range(20):
        c = np.zeros(20)
        c[k] = 1.0
        np.testing.assert_allclose(
            evaluate_rpc00b_polynomial(c, x, y, z),
            mono[:, k],
            rtol=0,
            atol=1e-15,
            err_msg=RPC00B_TERMS[k],
        )
    # closed-form check of the term order with distinct integer values
    m = rpc00b_monomials([2.0], [3.0], [5.0])[0]
    expected = [1, 2, 3, 5, 6, 10, 15, 4, 9, 25, 30, 8, 18, 50, 12, 27, 75, 20, 45, 125]
    np.testing.assert_array_equal(m, expected)


def test_affine_projection_closed_form():
    model = _affine_model()
    row, col = model.projection([5.0, 5.2], [45.0, 44.9], [0.0, 100.0])
    np.testing.assert_allclose(row, [500.0, 500.0 - 1000.0], atol=1e-9)
    np.testing.assert_allclose(col, [1000.0, 1000.0 + 2000.0], atol=1e-9)


@pytest.mark.parametrize("arg", ["lon", "lat", "h"])
def test_nan_ground_input_raises_naming_argument(arg):
    model = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    values = {"lon": -56.17, "lat": -34.9, "h": 10.0}
    values[arg] = np.array([values[arg], np.nan])
    with pytest.raises(ValueError, match=f"^{arg} contains NaN"):
        model.projection(values["lon"], values["lat"], values["h"])


@pytest.mark.parametrize("arg", ["row", "col", "h"])
def test_nan_image_input_raises_naming_argument(arg):
    model = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    values = {"row": 100.0, "col": 200.0, "h": 10.0}
    values[arg] = np.nan
    with pytest.raises(ValueError, match=f"^{arg} contains NaN"):
        model.localization(values["row"], values["col"], values["h"])


def test_shapes_are_preserved():
    model = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    lon = np.full((2, 3, 4), -56.17)
    row, col = model.projection(lon, -34.9, 0.0)
    assert row.shape == col.shape == (2, 3, 4)
    lon2, lat2, ok = model.localization(row, col, 0.0)
    assert lon2.shape == ok.shape == (2, 3, 4)


def test_non_convergence_is_flagged_and_strict_raises():
    """A model whose column does not depend on the ground point has no solution for col != 0."""
    model = _affine_model()
    degenerate = RationalFunctionModel(**{**model.__dict__, "col_num": np.r_[0.0, np.zeros(19)]})
    lon, lat, ok = degenerate.localization([500.0, 600.0], [1000.0, 1500.0], 0.0, max_iter=20)
    assert not ok.any()
    assert np.isnan(lon).all() and np.isnan(lat).all()
    with pytest.raises(ConvergenceError, match="2 of 2 point"):
        degenerate.localization([500.0, 600.0], [1000.0, 1500.0], 0.0, raise_on_failure=True)
    with pytest.raises(ConvergenceError):
        degenerate.localization_strict(500.0, 1000.0, 0.0)


def test_affine_localization_closed_form():
    model = _affine_model()
    lon, lat = model.localization_strict([500.0, 1500.0], [1000.0, 0.0], [0.0, 0.0])
    np.testing.assert_allclose(lon, [5.0, 5.0 - 0.1], atol=1e-12)
    np.testing.assert_allclose(lat, [45.0, 45.1], atol=1e-12)


def test_domain_defaults_and_in_domain():
    model = _affine_model()
    d = model.domain
    assert (d.lon_min, d.lon_max, d.lat_min, d.lat_max) == pytest.approx((4.8, 5.2, 44.9, 45.1))
    assert (d.h_min, d.h_max) == (-500.0, 500.0)
    mask = model.in_domain([5.0, 5.3], [45.0, 45.0], [0.0, 0.0])
    assert mask.tolist() == [True, False]
    # out-of-domain points are still evaluated (extrapolation), see docs/rpc.md
    row, col = model.projection(5.3, 45.0, 0.0)
    assert np.isfinite(row) and np.isfinite(col)


def test_localization_on_dem_recovers_ground_point_on_real_dem():
    from explorer.terrain_io import DEFAULT_ASSETS_DIR, read_geotiff_dem

    model = read_rpc(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    dem = read_geotiff_dem(DEFAULT_ASSETS_DIR / "MNT_P1BP--2018122638935449CP.tif")
    rng = np.random.default_rng(3)
    lon = rng.uniform(2.15, 2.3, 40)
    lat = rng.uniform(30.95, 31.1, 40)
    h = dem.height(lon, lat)
    assert np.isfinite(h).all()
    row, col = model.projection(lon, lat, h)
    lon_d, lat_d, h_d, found = localization_on_dem(model, row, col, dem)
    assert found.all()
    # Pleiades ~0.5 m pixels: 1e-7 deg ~ 1 cm; heights to the bisection tolerance scale
    np.testing.assert_allclose(lon_d, lon, atol=1e-7)
    np.testing.assert_allclose(lat_d, lat, atol=1e-7)
    np.testing.assert_allclose(h_d, h, atol=1e-2)


def test_localization_on_dem_takes_first_crossing_of_a_ridge():
    """A thin wall along the line of sight: the ray must stop on the wall, not the ground."""
    model = _affine_model()
    # for this model the line of sight is vertical; make it oblique by a height term
    tilted = RationalFunctionModel(
        **{**model.__dict__, "col_num": np.r_[0.0, 1.0, 0.0, 0.2, np.zeros(16)]}
    )
    wall_lon = 5.0 - 0.2 * 0.2 * (300.0 / 500.0)  # where the ray of col=1000 is at h=300 m

    def terrain(lon, lat):
        lon = np.asarray(lon)
        return np.where(np.abs(lon - wall_lon) < 2e-4, 400.0, 0.0)

    lon, lat, h, found = localization_on_dem(tilted,
        500.0, 1000.0, terrain, h_min=-10.0, h_max=1000.0, n_levels=400
    )
    assert found
    # stopped on the wall face: lon within the wall, h where the ray leaves it going down
    assert abs(lon - wall_lon) <= 2e-4 + 1e-9
    assert h == pytest.approx(300.0 + 2.5, abs=1e-2)
    # no crossing: terrain always below the search interval
    _, _, h2, found2 = localization_on_dem(tilted,
        500.0, 1000.0, lambda x, y: x * 0 - 50.0, h_min=0.0, h_max=100.0
    )
    assert not found2 and np.isnan(h2)
