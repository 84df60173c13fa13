"""The compiled (numba) projection equals the numpy path and rpcm, with the same input handling."""

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.rpc import RationalFunctionModel, _kernels, read_rpc

from .conftest import RPC_DIR, RPCM_READABLE, normalisation_grid

pytestmark = pytest.mark.skipif(not _kernels.NUMBA_AVAILABLE, reason="numba not available")

#: every file read_rpc reads (rpcm's set plus the formats only we read)
ALL_READABLE = RPCM_READABLE + [
    "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.geom",
    "PHRDIMAP_P1BP--2018122638935449CP.XML",
    "md_dg.RPB",
    "rpc.vrt",
    "rpc_5395.vrt",
]


@pytest.fixture(params=["serial", "parallel"])
def loop(request, monkeypatch):
    """Run the compiled path through its serial or its prange loop, whatever the input size."""
    monkeypatch.setattr(_kernels, "PARALLEL_MIN_POINTS", 0 if request.param == "parallel" else 10**12)
    return request.param


def _points(model, n, spread, seed):
    """n random points in offset +- spread * |scale| (spread > 1: outside the domain, extrapolated)."""
    rng = np.random.default_rng(seed)
    return tuple(
        off + spread * abs(scale) * rng.uniform(-1.0, 1.0, n)
        for off, scale in (
            (model.lon_offset, model.lon_scale),
            (model.lat_offset, model.lat_scale),
            (model.height_offset, model.height_scale),
        )
    )


@pytest.mark.parametrize("name", ALL_READABLE)
def test_compiled_equals_numpy_inside_and_outside_domain(name, loop):
    model = read_rpc(RPC_DIR / name)
    for spread, seed in ((1.0, 0), (3.0, 1)):  # inside, then up to 3x the normalisation box
        lon, lat, h = _points(model, 5000, spread, seed)
        row, col = model.projection(lon, lat, h, backend="numba")
        row_np, col_np = model.projection(lon, lat, h, backend="numpy")
        assert np.max(np.abs(row - row_np)) <= 1e-12
        assert np.max(np.abs(col - col_np)) <= 1e-12
    # outside the declared domain too: extrapolated, not masked (docs/rpc.md)
    assert not model.in_domain(lon, lat, h).all()
    assert np.isfinite(row).all() and np.isfinite(col).all()


@pytest.mark.parametrize("name", RPCM_READABLE)
def test_compiled_matches_rpcm_on_domain_grid(name, loop):
    rpcm = pytest.importorskip("rpcm")
    path = RPC_DIR / name
    ours = read_rpc(path)
    peer = rpcm.rpc_from_rpc_file(str(path))
    lon, lat, h = normalisation_grid(ours)
    row, col = ours.projection(lon, lat, h, backend="numba")
    col_ref, row_ref = peer.projection(lon, lat, h)
    assert np.max(np.abs(row - row_ref)) < 1e-6  # the tolerance of test_rpc_peer.py
    assert np.max(np.abs(col - col_ref)) < 1e-6


@pytest.mark.parametrize("arg", ["lon", "lat", "h"])
@pytest.mark.parametrize("scalar_nan", [False, True])
def test_nan_input_raises_the_numpy_paths_error(arg, scalar_nan, loop):
    model = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    values = {"lon": np.full(4, -56.17), "lat": np.full(4, -34.9), "h": np.full(4, 10.0)}
    if scalar_nan:  # a scalar NaN broadcast against arrays: the count is of the argument as given
        values[arg] = np.nan
    else:
        values[arg] = values[arg].copy()
        values[arg][[1, 3]] = np.nan
    messages = []
    for backend in ("numba", "numpy"):
        with pytest.raises(ValueError, match=f"^{arg} contains NaN") as info:
            model.projection(values["lon"], values["lat"], values["h"], backend=backend)
        messages.append(str(info.value))
    assert messages[0] == messages[1]
    assert messages[0].endswith(f"({1 if scalar_nan else 2} value(s))")


def test_first_nan_argument_is_named_when_several_have_nan():
    model = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    with pytest.raises(ValueError, match="^lat contains NaN"):
        model.projection([-56.17, -56.17], [np.nan, -34.9], [np.nan, 1.0], backend="numba")


def test_shapes_types_and_broadcasting_match_numpy(loop):
    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    lon = model.lon_offset + model.lon_scale * np.linspace(-1, 1, 7)
    lat = model.lat_offset + model.lat_scale * np.linspace(-1, 1, 5)
    cases = [
        (float(lon[2]), float(lat[1]), 12.0),  # scalars -> numpy float64 scalars
        ([float(v) for v in lon], float(lat[0]), 0),  # list, scalar, int
        (lon[:, None], lat[None, :], np.array(7.5)),  # (7, 1) x (1, 5) -> (7, 5)
        (np.asfortranarray(np.tile(lon, (3, 1))), lat[0], np.zeros((3, 7))),  # Fortran order
        (lon[::2], lat[:4], np.arange(4, dtype=np.int32)),  # strided view, integer heights
        (np.empty(0), np.empty(0), np.empty(0)),
    ]
    for a, b, c in cases:
        row, col = model.projection(a, b, c, backend="numba")
        row_np, col_np = model.projection(a, b, c, backend="numpy")
        assert type(row) is type(row_np) and type(col) is type(col_np)
        assert np.shape(row) == np.shape(row_np) and np.shape(col) == np.shape(col_np)
        np.testing.assert_array_equal(row, row_np)
        np.testing.assert_array_equal(col, col_np)


def test_inputs_are_not_modified():
    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    lon, lat, h = _points(model, 1000, 1.0, 3)
    copies = (lon.copy(), lat.copy(), h.copy())
    model.projection(lon, lat, h, backend="numba")
    for a, b in zip((lon, lat, h), copies, strict=True):
        np.testing.assert_array_equal(a, b)


def test_shapes_that_do_not_broadcast_raise_like_numpy():
    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    for backend in ("numba", "numpy"):
        with pytest.raises(ValueError):
            model.projection(np.zeros(3), np.zeros(4), 0.0, backend=backend)


def test_zero_denominator_and_infinite_inputs_give_the_same_non_finite_values(loop):
    num = np.zeros(20)
    num[0] = 1.0
    den = np.zeros(20)
    den[0], den[1] = -2.0, 1.0  # denominator = L - 2: zero at lon = lon_offset + 2, outside the domain
    kwargs = dict(row_offset=0.0, col_offset=0.0, lat_offset=0.0, lon_offset=10.0, height_offset=0.0,
                  row_scale=1.0, col_scale=1.0, lat_scale=1.0, lon_scale=1.0, height_scale=1.0)
    model = RationalFunctionModel(row_num=num, row_den=den, col_num=num, col_den=den, **kwargs)
    lon = np.array([12.0, 11.0, 9.0, 12.0 + 1e-300])
    with np.errstate(divide="ignore", invalid="ignore"):
        row, col, valid = model.projection(lon, 0.0, 0.0, backend="numba", return_valid=True)
        row_np, col_np = model.projection(lon, 0.0, 0.0, backend="numpy")
    np.testing.assert_array_equal(row, row_np)  # NaN == NaN here
    np.testing.assert_array_equal(col, col_np)
    assert np.isinf(row[0]) and row[1] == -1.0 and row[2] == -1.0 / 3.0
    np.testing.assert_array_equal(valid, [False, True, True, False])  # |L| = 2 is outside the domain
    # infinite inputs are refused by both paths (issue 18), naming the input
    for backend in ("numba", "numpy"):
        with pytest.raises(InputError, match="lon contains infinite"):
            model.projection(np.array([11.0, np.inf]), 0.0, 0.0, backend=backend)
    # a denominator that vanishes inside the domain (L = 0) is refused by validate() (the readers call it)
    den_zero = np.zeros(20)
    den_zero[1] = 1.0
    with pytest.raises(InputError, match="LINE_DEN_COEFF"):
        RationalFunctionModel(row_num=num, row_den=den_zero, col_num=num, col_den=den, **kwargs).validate()


def test_backend_argument_is_checked():
    model = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    with pytest.raises(ValueError, match="backend must be"):
        model.projection(model.lon_offset, model.lat_offset, 0.0, backend="cuda")
