import numpy as np
import pytest

from explorer.errors import InputError
from explorer.points import PointSet, image_grid, simulate_points
from explorer.presets import build_scene


def test_grid_count_and_exact_rows():
    scene = build_scene("SCB")
    pts = simulate_points(scene, 100, kind="scop")
    gr, gc, gl = pts.grid_shape
    assert len(pts) == 100 and gr * (gc - 1) < 100 <= gr * gc  # exactly the count chosen (issue 24)
    assert pts.row.min() == 0 and pts.row.max() == scene.n_rows - 1
    # exact: the collinearity residual vanishes at each point's time
    r = scene.along_track_residual(pts.ground, pts.time) / scene.pixel_size_m
    assert np.max(np.abs(r)) < 1e-9
    np.testing.assert_allclose(scene.column_at_time(pts.ground, pts.time), pts.col, atol=1e-9)


@pytest.mark.parametrize("preset", ["SCB", "WSU", "PMA"])
@pytest.mark.parametrize("n", [10, 20, 30, 50, 99, 100, 101, 300, 500, 1000, 1003])
def test_scop_count_is_the_one_chosen(preset, n):
    """Issue 24: choosing n SCOPs gives n (not 99 or 105), on a layout that keeps the four image
    corners and the first / last row and column, with grid rows differing by at most one point."""
    scene = build_scene(preset)
    pts = simulate_points(scene, n, kind="scop")
    assert len(pts) == n
    corners = {(0.0, 0.0), (0.0, scene.n_columns - 1.0), (scene.n_rows - 1.0, 0.0),
               (scene.n_rows - 1.0, scene.n_columns - 1.0)}
    assert corners <= set(zip(pts.row.tolist(), pts.col.tolist(), strict=True))
    _, per_row = np.unique(pts.row, return_counts=True)
    assert per_row.max() - per_row.min() <= 1
    # every point exact: the collinearity residual vanishes at its time (independent of the generator)
    r = scene.along_track_residual(pts.ground, pts.time) / scene.pixel_size_m
    assert np.max(np.abs(r)) < 1e-9


def test_fast_grid_path_equals_general_path():
    scene = build_scene("PMA")
    fast = simulate_points(scene, 400, kind="scp")
    general = scene.image_to_ground(fast.row, fast.col)
    np.testing.assert_allclose(fast.ground, general, atol=1e-7)


@pytest.mark.parametrize("layers", [1, 3])
def test_points_of_a_rigorous_scene_lie_on_its_own_lines_of_sight(layers):
    """A rigorous line-scan model corrects its lines of sight (aberration of light, refraction); the grid's
    ground points are where the model's own (bracketing, independent) ground to image puts them back.  The
    grid once took the uncorrected lines of sight on a flat terrain: 26 px off on WorldView-1."""
    from explorer.real.worldview import rigorous_scene_from_dg

    from .real.conftest import WV1

    scene = rigorous_scene_from_dg(WV1)
    assert scene.aberration and scene.refraction
    pts = image_grid(scene, 60, layers=layers)
    row, col = scene.ground_to_image(pts.ground)
    assert np.max(np.hypot(row - pts.row, col - pts.col)) < 1e-5


def test_scp_grid_differs_from_scop_grid():
    scene = build_scene("WSU")
    a = simulate_points(scene, 100, kind="scop")
    b = simulate_points(scene, 100, kind="scp")
    assert not np.intersect1d(a.row, b.row).size


def test_3d_grid_layers():
    scene = build_scene("WSU")
    pts = image_grid(scene, 100, layers=5, height_range=(-200.0, 600.0))
    assert pts.grid_shape[2] == 5 and len(pts) == 5 * 100
    assert set(np.round(pts.ground[:, 2], 6)) == {-200.0, 0.0, 200.0, 400.0, 600.0}


def test_dem_grid_heights_on_dem():
    scene = build_scene("WSU", relief_m=600.0, relief_seed=1)
    pts = simulate_points(scene, 200)
    np.testing.assert_allclose(pts.ground[:, 2], scene.terrain.height(pts.ground[:, 0], pts.ground[:, 1]), atol=1e-6)


def test_seeded_jitter_and_split():
    scene = build_scene("WSU")
    a = image_grid(scene, 100, jitter_px=0.4, seed=3)
    b = image_grid(scene, 100, jitter_px=0.4, seed=3)
    np.testing.assert_array_equal(a.ground, b.ground)
    tr, va = a.split(0.7, seed=1)
    assert len(tr) == 70 and len(va) == len(a) - 70


def test_npz_round_trip(tmp_path):
    scene = build_scene("WSU")
    pts = simulate_points(scene, 50)
    pts.save_npz(tmp_path / "p.npz", scene)
    back = PointSet.load_npz(tmp_path / "p.npz")
    np.testing.assert_array_equal(back.ground, pts.ground)
    with np.load(tmp_path / "p.npz") as z:
        assert "scene_json" in z


def test_bad_counts():
    with pytest.raises(InputError):
        simulate_points(build_scene("WSU"), 2)
    with pytest.raises(InputError):
        simulate_points(build_scene("WSU"), 100, kind="gcp")
