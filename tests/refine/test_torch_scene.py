"""The differentiable MPC scene (torch) against the compiled ground to image, finite differences, and the
recovery of a known exterior perturbation of the MPC scene of a planetary camera (MRO CTX ISD)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from explorer.geometry.exterior import Jitter  # noqa: E402
from explorer.presets import build_scene  # noqa: E402
from explorer.real.csm import scene_from_isd  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.refine.torch_scene import SCENE_MODELS, TorchScene, adjusted_scene  # noqa: E402

CTX = Path(__file__).resolve().parents[1] / "data" / "usgscsm" / "ctxLineScan.json"
DRIFT = np.array([5.0, -3.0, 2.0, 1e-5, -2e-5, 3e-5, 0.1, 0.2, -0.1, 1e-6, -1e-6, 2e-6])


@pytest.fixture(scope="module")
def ctx():
    return scene_from_isd(str(CTX))


def _jittery():
    return build_scene("WSU", extra_jitter=[Jitter("phi", 2e-6, 37.0, 0.3), Jitter("omega", 1e-6, 11.0, 1.0)])


def _ground(scene, n=400, seed=0):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0, scene.n_rows - 1, n)
    c = rng.uniform(0, scene.n_columns - 1, n)
    return scene.image_to_ground(r, c, height=rng.uniform(-300, 300, n))


@pytest.mark.parametrize("which", ["wsu", "jitter", "ctx"])
@pytest.mark.parametrize("model", list(SCENE_MODELS))
def test_torch_scene_equals_the_compiled_path(which, model, ctx):
    """Curved detector line, uneven spacing (CTX), jitter: within 1e-9 px of Scene.ground_to_image of the
    adjusted scene, with zero and with non-zero corrections."""
    scene = {"wsu": build_scene("WSU"), "jitter": _jittery(), "ctx": ctx}[which]
    ground = _ground(scene)
    n_par = len(SCENE_MODELS[model])
    for params in (np.zeros(n_par), DRIFT[:n_par]):
        row, col = TorchScene(scene, model).project_enu(torch.from_numpy(ground), torch.from_numpy(params))
        want_row, want_col = adjusted_scene(scene, model, params).ground_to_image(ground)
        assert np.isfinite(want_row).all()
        assert np.max(np.abs(row.detach().numpy() - want_row)) < 1e-9
        assert np.max(np.abs(col.detach().numpy() - want_col)) < 1e-9


def test_geodetic_to_enu_in_torch_matches_the_frame(ctx):
    ground = _ground(ctx)
    lon, lat, h = ctx.frame.enu_to_geodetic(ground)
    got = TorchScene(ctx).enu(*(torch.from_numpy(v) for v in (lon, lat, h))).numpy()
    assert np.max(np.abs(got - ctx.frame.geodetic_to_enu(lon, lat, h))) < 1e-8  # body-fixed rounding, metres


@pytest.mark.parametrize("which", ["jitter", "ctx"])
def test_scene_gradients_match_finite_differences(which, ctx):
    """d(row, col)/d(ground, corrections) by autograd (implicit derivative of the best scanline) against
    central differences of the compiled path of the adjusted scene."""
    scene = ctx if which == "ctx" else _jittery()
    model = "attitude-drift"
    ground = _ground(scene, 30, seed=4)
    params = DRIFT.copy()
    g = torch.tensor(ground, requires_grad=True)
    theta = torch.tensor(np.repeat(params[None], len(ground), axis=0), requires_grad=True)
    row, col = TorchScene(scene, model).project_enu(g, theta)

    def compiled(gr, p):
        return adjusted_scene(scene, model, p).ground_to_image(gr)

    steps = np.array([0.05, 0.05, 0.05, 1e-8, 1e-8, 1e-8, 0.01, 0.01, 0.01, 1e-7, 1e-7, 1e-7])
    for k, value in enumerate((row, col)):
        g_ground, g_theta = torch.autograd.grad(value.sum(), (g, theta), retain_graph=True)
        for axis in range(3):
            d = np.zeros(3)
            d[axis] = 0.05
            fd = (compiled(ground + d, params)[k] - compiled(ground - d, params)[k]) / 0.1
            np.testing.assert_allclose(g_ground.numpy()[:, axis], fd, rtol=1e-5, atol=1e-9 / 0.05)
        for j in range(12):
            dp = np.zeros(12)
            dp[j] = steps[j]
            fd = (compiled(ground, params + dp)[k] - compiled(ground, params - dp)[k]) / (2 * steps[j])
            # central differences carry the compiled roots' rounding (1e-10 px) divided by the step
            np.testing.assert_allclose(g_theta.numpy()[:, j], fd, rtol=1e-5, atol=1e-9 / steps[j])


def test_recovers_a_known_perturbation_of_a_planetary_camera(ctx):
    """The MPC scene of the CTX camera moved by 30 / -20 / 15 m and turned by 2e-5 / -3e-5 / 5e-5 rad, 40 GCPs
    and 300 check points with 0.3 px noise (seeded): corrections within 3 sigmas, check RMSE within 10 %."""
    true = np.array([30.0, -20.0, 15.0, 2e-5, -3e-5, 5e-5])
    biased = adjusted_scene(ctx, "attitude", true)

    def simulate(n, seed, prefix):
        rng = np.random.default_rng(seed)
        ground = _ground(ctx, n, seed)
        row, col = biased.ground_to_image(ground)
        lon, lat, h = ctx.frame.enu_to_geodetic(ground)
        return PointTable([f"{prefix}{i}" for i in range(n)], row + rng.normal(0, 0.3, n),
                          col + rng.normal(0, 0.3, n), lon, lat, h)

    ref = refine_images([ctx], model="attitude", control=simulate(40, 1, "g"), check=simulate(300, 2, "c"),
                        sigma_px=0.3)
    z = (ref.parameters - true) / ref.result.parameter_sigma
    assert np.all(np.abs(z) < 3.0), z
    rep = ref.report()
    assert rep["check_rmse_px_before"] > 3.0
    assert abs(rep["check_rmse_px"] - 0.3) < 0.03
    # on a narrow-angle camera GCPs barely separate a position offset from a turn: the report says so
    assert abs(ref.result.parameter_correlation[1, 3]) > 0.99
