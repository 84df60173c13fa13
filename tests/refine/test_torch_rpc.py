"""The differentiable RPC (torch) against the compiled projection, closed-form and finite-difference derivatives."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from explorer.refine.corrections import CORRECTION_PARAMETERS, apply_correction  # noqa: E402
from explorer.refine.torch_rpc import TorchRPC  # noqa: E402
from explorer.rpc import read_rpc  # noqa: E402
from explorer.rpc.polynomial import _rpc00b_polynomial_and_gradient  # noqa: E402
from tests.refine.cases import PAIR, PLEIADES, RPC_DIR  # noqa: E402

FILES = [PLEIADES, PAIR[0], RPC_DIR / "rpc_WV2.xml", RPC_DIR / "rpc_IKONOS.txt", RPC_DIR / "test_rpc.txt"]


def _grid(rpc, n=2000, seed=3):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, (n, 3))
    return (rpc.lon_offset + u[:, 0] * rpc.lon_scale, rpc.lat_offset + u[:, 1] * rpc.lat_scale,
            rpc.height_offset + u[:, 2] * rpc.height_scale)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_torch_projection_equals_the_compiled_path(path):
    rpc = read_rpc(path)
    lon, lat, h = _grid(rpc)
    want_row, want_col = rpc.projection(lon, lat, h)  # the compiled (numba) path
    model = TorchRPC(rpc, "affine")
    row, col = model.model_pixels(*(torch.from_numpy(v) for v in (lon, lat, h)))
    assert row.dtype == torch.float64
    assert np.max(np.abs(row.numpy() - want_row)) < 1e-9
    assert np.max(np.abs(col.numpy() - want_col)) < 1e-9
    params = np.array([3.0, 2e-4, -1e-4, -2.0, 1e-4, 3e-4])
    row, col = model.project(*(torch.from_numpy(v) for v in (lon, lat, h)), torch.from_numpy(params))
    want = apply_correction("affine", params, want_row, want_col)
    assert np.max(np.abs(row.numpy() - want[0])) < 1e-9
    assert np.max(np.abs(col.numpy() - want[1])) < 1e-9


@pytest.mark.parametrize("path", [PLEIADES, RPC_DIR / "rpc_WV2.xml"], ids=lambda p: p.name)
def test_ground_gradients_match_the_closed_form(path):
    """d(row, col)/d(lon, lat) by autograd against the quotient rule on the analytic polynomial derivatives."""
    rpc = read_rpc(path)
    lon, lat, h = _grid(rpc, 300)
    tl, tp, th = (torch.tensor(v, requires_grad=True) for v in (lon, lat, h))
    row, col = TorchRPC(rpc, "shift").model_pixels(tl, tp, th)
    x, y, z = rpc._normalise_ground(lon, lat, h)
    for value, num, den, scale in ((row, rpc.row_num, rpc.row_den, rpc.row_scale),
                                   (col, rpc.col_num, rpc.col_den, rpc.col_scale)):
        g_lon, g_lat = torch.autograd.grad(value.sum(), (tl, tp), retain_graph=True)
        n, n_x, n_y = _rpc00b_polynomial_and_gradient(num, x, y, z)
        d, d_x, d_y = _rpc00b_polynomial_and_gradient(den, x, y, z)
        want_lon = scale * (n_x * d - n * d_x) / d**2 / rpc.lon_scale
        want_lat = scale * (n_y * d - n * d_y) / d**2 / rpc.lat_scale
        np.testing.assert_allclose(g_lon.numpy(), want_lon, rtol=1e-10, atol=1e-9 * np.max(np.abs(want_lon)))
        np.testing.assert_allclose(g_lat.numpy(), want_lat, rtol=1e-10, atol=1e-9 * np.max(np.abs(want_lat)))


@pytest.mark.parametrize("model", list(CORRECTION_PARAMETERS))
def test_all_gradients_match_finite_differences(model):
    """Every derivative (ground and correction parameters) against central differences of the numpy path."""
    rpc = read_rpc(PLEIADES)
    lon, lat, h = _grid(rpc, 50, seed=5)
    n_par = len(CORRECTION_PARAMETERS[model])
    params = np.random.default_rng(2).normal(0.0, 1e-6, n_par)
    params[0] = 2.0
    inputs = [torch.tensor(v, requires_grad=True) for v in (lon, lat, h)]
    theta = torch.tensor(np.repeat(params[None], lon.size, axis=0), requires_grad=True)
    row, col = TorchRPC(rpc, model).project(*inputs, theta)

    def numpy_path(lo, la, hh, p):
        r, c = rpc.projection(lo, la, hh)
        return apply_correction(model, p, r, c)

    steps = (1e-7, 1e-7, 1e-2)
    for k, value in enumerate((row, col)):
        grads = torch.autograd.grad(value.sum(), (*inputs, theta), retain_graph=True)
        for axis, step in enumerate(steps):
            args_p = [lon, lat, h]
            args_m = [lon, lat, h]
            args_p[axis] = args_p[axis] + step
            args_m[axis] = args_m[axis] - step
            fd = (numpy_path(*args_p, params)[k] - numpy_path(*args_m, params)[k]) / (2 * step)
            np.testing.assert_allclose(grads[axis].numpy(), fd, rtol=1e-5, atol=1e-4 * np.max(np.abs(fd)))
        for j in range(n_par):
            step = 1e-3 if j in (0, n_par // 2) else 1e-9
            dp = np.zeros(n_par)
            dp[j] = step
            fd = (numpy_path(lon, lat, h, params + dp)[k] - numpy_path(lon, lat, h, params - dp)[k]) / (2 * step)
            np.testing.assert_allclose(grads[3][:, j].numpy(), fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(fd)))


def test_affine_parameter_gradients_are_the_model_pixels():
    """Closed form: d row/d row_per_row = row_model, d row/d row_per_col = col_model, d row/d row_shift = 1."""
    rpc = read_rpc(PLEIADES)
    lon, lat, h = _grid(rpc, 100)
    theta = torch.zeros((lon.size, 6), dtype=torch.float64, requires_grad=True)
    model = TorchRPC(rpc, "affine")
    row, col = model.project(*(torch.from_numpy(v) for v in (lon, lat, h)), theta)
    r0, c0 = rpc.projection(lon, lat, h)
    (g_row,) = torch.autograd.grad(row.sum(), theta)
    np.testing.assert_allclose(g_row.numpy()[:, :3], np.stack([np.ones_like(r0), r0, c0], axis=1), rtol=1e-14)
    assert np.all(g_row.numpy()[:, 3:] == 0.0)
