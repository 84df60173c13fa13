"""3D scene builders: the display frame, the sampled geometry against independent truth
(brute-force best scanlines, closed-form quaternions) and the viser nodes they add."""

from __future__ import annotations

import io

import numpy as np
import pytest

from explorer.panels import HEIGHT, ITERATION, SCOP_RGB
from explorer.presets import build_scene
from explorer.scene3d import builders as B
from tests.truth import brute_force_rows

viser = pytest.importorskip("viser")


@pytest.fixture(scope="module")
def scene():
    return build_scene("WSU")


@pytest.fixture(scope="module")
def relief_scene():
    return build_scene("WSU", relief_m=800.0, relief_seed=2)


@pytest.fixture
def api():
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield srv.scene
    srv.stop()


def test_display_frame_is_kilometres_from_the_scene_centre(scene):
    f = B.DisplayFrame.for_scene(scene, height_exaggeration=3.0)
    c = B.scene_centre(scene)
    np.testing.assert_allclose(f.ground(c[None]), 0.0, atol=1e-12)
    p = c + np.array([1500.0, -250.0, 300.0])
    np.testing.assert_allclose(f.ground(p[None])[0], [1.5, -0.25, 0.9], atol=1e-12)
    # the centre is the image centre on the mean-height plane (independent truth)
    assert abs(brute_force_rows(scene, c[None])[0] - (scene.n_rows - 1) / 2) < 1e-6
    assert abs(scene.column_at_row(c[None], np.array([(scene.n_rows - 1) / 2]))[0]
               - (scene.n_columns - 1) / 2) < 1e-6
    assert c[2] == scene.terrain.mean_height


def test_compressed_sensor_distance_keeps_direction_length_and_shape(scene):
    f = B.DisplayFrame.for_scene(scene)
    t = B.DisplayFrame.for_scene(scene, sensor_distance="true")
    c = B.scene_centre(scene)
    s_mid = scene.exterior.position(scene.scanline_time(np.array([(scene.n_rows - 1) / 2])))[0]
    d_true = (s_mid - c) / 1000.0
    d_disp = f.sensor(s_mid[None])[0]
    assert np.linalg.norm(d_disp) == pytest.approx(B.COMPRESSED_DISTANCE_FACTOR * f.diagonal_km, rel=1e-12)
    np.testing.assert_allclose(d_disp / np.linalg.norm(d_disp), d_true / np.linalg.norm(d_true), atol=1e-12)
    np.testing.assert_allclose(t.sensor(s_mid[None])[0], d_true, atol=1e-9)
    assert np.linalg.norm(d_true) > 700.0  # ~700 km up, a few km footprint
    _, pos = B.track_positions(scene, 5)
    np.testing.assert_allclose(np.diff(f.sensor(pos), axis=0), np.diff(pos, axis=0) / 1000.0, atol=1e-9)
    with pytest.raises(ValueError):
        B.DisplayFrame.for_scene(scene, sensor_distance="far")


def _quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def test_sensor_frame_quaternions_reproduce_the_attitude(scene):
    rows, pos, wxyz = B.attitude_samples(scene, 7)
    rot = scene.exterior.rotation(scene.scanline_time(rows))
    np.testing.assert_allclose(pos, scene.exterior.position(scene.scanline_time(rows)))
    for q, r in zip(wxyz, rot, strict=True):
        assert abs(np.linalg.norm(q) - 1) < 1e-12 and q[0] >= 0
        np.testing.assert_allclose(_quat_to_matrix(q), r, atol=1e-12)
        v = viser.transforms.SO3.from_matrix(r).wxyz
        np.testing.assert_allclose(q, v * np.sign(v[0]), atol=1e-9)
    # a rotation by pi (w = 0) is recovered as well
    r_pi = np.diag([1.0, -1.0, -1.0])
    np.testing.assert_allclose(_quat_to_matrix(B.quaternion_wxyz(r_pi[None])[0]), r_pi, atol=1e-12)


def test_footprint_mesh_lies_on_the_terrain_and_spans_the_image(relief_scene):
    sc = relief_scene
    n = 9
    v, faces = B.footprint_mesh(sc, n)
    assert v.shape == (n * n, 3) and faces.shape == (2 * (n - 1) ** 2, 3)
    assert faces.min() == 0 and faces.max() == n * n - 1
    np.testing.assert_allclose(v[:, 2], sc.terrain.height(v[:, 0], v[:, 1]), atol=1e-6)
    corners = v[[0, n - 1, n * n - n, n * n - 1]]
    rows = brute_force_rows(sc, corners, margin=5)
    np.testing.assert_allclose(rows, [-0.5, -0.5, sc.n_rows - 0.5, sc.n_rows - 0.5], atol=1e-6)
    cols = sc.column_at_row(corners, rows)
    np.testing.assert_allclose(cols, [-0.5, sc.n_columns - 0.5, -0.5, sc.n_columns - 0.5], atol=1e-6)
    seg = B.footprint_outline(sc, per_edge=8)
    assert seg.shape == (32, 2, 3)
    np.testing.assert_allclose(seg[1:, 0], seg[:-1, 1], atol=1e-9)  # a closed chain
    np.testing.assert_allclose(seg[0, 0], seg[-1, 1], atol=1e-9)


def test_scanline_planes_pass_through_the_centre_and_the_scanline(scene):
    rows = np.array([0.0, 1000.25, scene.n_rows - 1.0])
    centres, ends = B.scanline_planes(scene, rows, 250.0)
    np.testing.assert_allclose(centres, scene.exterior.position(scene.scanline_time(rows)))
    assert np.allclose(ends[..., 2], 250.0)
    flat = ends.reshape(-1, 3)
    np.testing.assert_allclose(brute_force_rows(scene, flat, margin=5), np.repeat(rows, 2), atol=1e-6)
    np.testing.assert_allclose(scene.column_at_row(flat, np.repeat(rows, 2)),
                               np.tile([-0.5, scene.n_columns - 0.5], 3), atol=1e-6)


def test_ground_mesh_vertex_colours_follow_height(api, relief_scene):
    import trimesh

    f = B.DisplayFrame.for_scene(relief_scene)
    out = B.add_ground(api, relief_scene, f, n=11)
    assert set(out) == {"/ground/surface", "/ground/outline"}
    # read the GLB back with an independent reader
    scene_glb = trimesh.load(io.BytesIO(out["/ground/surface"].glb_data), file_type="glb", process=False)
    (glb,) = scene_glb.geometry.values()
    v, faces = B.footprint_mesh(relief_scene, 11)
    np.testing.assert_allclose(np.asarray(glb.vertices), f.ground(v), atol=1e-5)
    np.testing.assert_array_equal(np.asarray(glb.faces), faces)
    colors = np.asarray(glb.visual.vertex_attributes["color"])
    lo, hi = relief_scene.terrain.min_height, relief_scene.terrain.max_height
    np.testing.assert_array_equal(colors[:, :3], B.height_rgb(v[:, 2], lo, hi))
    assert (colors[:, 3] == 255).all()
    low = np.argmin(v[:, 2])
    assert np.abs(colors[low, :3].astype(int) - np.array(HEIGHT[0][1])).max() <= np.abs(
        colors[np.argmax(v[:, 2]), :3].astype(int) - np.array(HEIGHT[0][1])).max()
    # normals point up (the ground is seen from above)
    assert (B.vertex_normals(f.ground(v), faces)[:, 2] > 0).all()
    # without relief: one flat colour
    flat = B.add_ground(api, build_scene("WSU"), B.DisplayFrame.for_scene(build_scene("WSU")), n=5)
    (g2,) = trimesh.load(io.BytesIO(flat["/ground/surface"].glb_data), file_type="glb").geometry.values()
    assert len(np.unique(np.asarray(g2.visual.vertex_attributes["color"]), axis=0)) == 1


def test_orbit_and_planes_nodes(api, scene):
    f = B.DisplayFrame.for_scene(scene)
    orbit = B.add_orbit(api, scene, f, n_frames=5)
    assert orbit["/orbit/sensor_frames"].batched_positions.shape == (5, 3)
    assert orbit["/orbit/flight_label"].text == "flight direction"
    rows = np.array([0.0, 2000.0, scene.n_rows - 1.0, 1500.0])
    planes = B.add_scanline_planes(api, scene, f, rows, 60.0, ["first", "mid", "last", ""])
    assert sorted(k for k in planes if k.startswith("/scanlines/planes/")) == [f"/scanlines/planes/{i}"
                                                                              for i in range(4)]
    edges = planes["/scanlines/edges"].points
    assert edges.shape == (12, 2, 3)
    assert sorted(k for k in planes if "labels" in k) == [f"/scanlines/labels/{i}" for i in range(3)]
    # the first triangle's apex is the perspective centre of row 0 (displayed), its base the row's ground trace
    np.testing.assert_allclose(edges[0, 0], f.sensor(scene.exterior.position(scene.scanline_time(rows[:1])))[0],
                               atol=1e-5)
    ends = f.ground(B.scanline_footprints(scene, rows[:1], 60.0).reshape(-1, 3))
    np.testing.assert_allclose(edges[0, 1], ends[0], atol=1e-5)
    np.testing.assert_allclose(edges[4, 1], ends[1], atol=1e-5)  # segment 4: vertex 1 -> 2 of triangle 0
    # each plane's image is its triangle (texel centres inside it are opaque-ish, outside transparent)
    img = planes["/scanlines/planes/0"]
    assert float(img.render_width) > 0 and float(img.render_height) > 0
    # only the planes asked for are filled; every one keeps its outline
    some = B.add_scanline_planes(api, scene, f, rows, 60.0, ["first", "mid", "last", ""], filled=[3])
    assert [k for k in some if k.startswith("/scanlines/planes/")] == ["/scanlines/planes/3"]
    assert some["/scanlines/edges"].points.shape == (12, 2, 3)


def _texel_points(rgba, width, height, position, rotation):
    """Display-frame position (H, W, 3) of every texel centre, by viser's image convention: the plane is
    turned half a turn about x (ViserImage: ``rotation={new Euler(PI, 0, 0)}``) so texture row 0 (its top,
    three.js flips textures on upload) lies at local -y and column 0 at local -x."""
    n_h, n_w = rgba.shape[:2]
    x = -width / 2 + (np.arange(n_w) + 0.5) * width / n_w
    y = -height / 2 + (np.arange(n_h) + 0.5) * height / n_h
    xx, yy = np.meshgrid(x, y)
    local = np.stack([xx, yy, np.zeros_like(xx)], axis=-1)
    return position + local @ rotation.T


@pytest.mark.parametrize("triangle", [
    np.array([[0.0, 0.0, 20.0], [-3.0, -1.0, 0.0], [4.0, 1.5, 0.2]]),       # a scanline plane: tall, thin
    np.array([[1.0, 2.0, 3.0], [2.0, 2.5, 2.0], [0.5, 4.0, 2.5]]),          # an oblique one
    np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),          # seen from below (normal -z)
])
def test_triangle_texture_covers_exactly_its_triangle(triangle):
    rgba, w, h, pos, rot = B.triangle_texture(triangle, (90, 160, 255), 0.22, px=128)
    assert rgba.dtype == np.uint8 and rgba.shape[2] == 4 and max(rgba.shape[:2]) == 128
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) > 0  # a proper rotation (viser takes it as a quaternion)
    pts = _texel_points(rgba, w, h, pos, rot)
    # every texel lies in the triangle's plane
    normal = np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0])
    normal /= np.linalg.norm(normal)
    assert np.abs((pts - triangle[0]) @ normal).max() < 1e-9
    # barycentric coordinates of each texel centre (least squares in the plane): inside <=> all >= 0
    m = np.stack([triangle[1] - triangle[0], triangle[2] - triangle[0]], axis=1)
    ab = np.linalg.lstsq(m, (pts - triangle[0]).reshape(-1, 3).T, rcond=None)[0]
    bary = np.stack([1 - ab[0] - ab[1], ab[0], ab[1]]).T.reshape(rgba.shape[0], rgba.shape[1], 3)
    texel = max(w / rgba.shape[1], h / rgba.shape[0])
    edge = np.min(bary, axis=2) * np.linalg.norm(m, axis=0).min()  # ~ distance to the nearest edge (scaled)
    alpha = rgba[..., 3]
    clear_in, clear_out = edge > 2 * texel, np.min(bary, axis=2) < -0.02
    assert (alpha[clear_in] == round(0.22 * 255)).all() and (rgba[clear_in, :3] == (90, 160, 255)).all()
    assert (alpha[clear_out] == 0).all()
    # the rectangle is the triangle's bounding box in its plane: every vertex within half a texel of its edge
    local = (triangle - pos) @ rot
    assert np.all(np.abs(local[:, 0]) <= w / 2 + 1e-9) and np.all(np.abs(local[:, 1]) <= h / 2 + 1e-9)
    assert np.isclose(np.abs(local[:, 0]).max(), w / 2) and np.isclose(np.abs(local[:, 1]).max(), h / 2)
    # and the triangle covers about half of it (area ratio, within the texel rounding)
    area = 0.5 * np.linalg.norm(np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0]))
    assert abs((alpha > 0).mean() - area / (w * h)) < 0.03


def test_triangle_texture_refuses_a_degenerate_triangle():
    with pytest.raises(ValueError, match="degenerate"):
        B.triangle_texture(np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]]), (1, 2, 3), 0.5)


def test_selection_trace_is_coloured_first_to_last(api, scene):
    f = B.DisplayFrame.for_scene(scene)
    g = scene.image_to_ground(np.array([700.0]), np.array([900.0]))[0]
    trace = np.array([1997.5, 998.0, 700.3, 700.0, np.nan])
    out = B.add_selection(api, scene, f, g, 700.0, trace, max_labels=2)
    seg = out["/selected/trace"]
    assert seg.points.shape == (4, 2, 3)
    assert tuple(seg.colors[0, 0]) == ITERATION[0][1] and tuple(seg.colors[-1, 0]) == ITERATION[-1][1]
    assert sorted(k for k in out if "trace_labels" in k) == ["/selected/trace_labels/0",
                                                             "/selected/trace_labels/3"]
    ends = np.stack([np.asarray(out[k].position) for k in ("/selected/trace_labels/3",)])
    # the last visited scanline's trace passes through the point (its exact row is 700)
    p = f.ground(g[None])[0]
    a, b = seg.points[-1].astype(np.float64)
    dist = np.linalg.norm(np.cross(b - a, a - p)) / np.linalg.norm(b - a)
    assert dist < 1e-5 and ends.shape == (1, 3)
    none = B.add_selection(api, scene, f, g, 700.0, None)
    assert "/selected/trace" not in none


def test_scops_are_gold(api, scene):
    f = B.DisplayFrame.for_scene(scene)
    g = scene.image_to_ground(np.array([0.0, 100.0]), np.array([0.0, 100.0]))
    out = B.add_scops(api, f, g)
    node = out["/points/scops"]
    assert node.points.shape == (2, 3) and tuple(node.colors) == SCOP_RGB


def test_real_dem_ground_mesh_follows_the_dem_and_is_decimated_for_the_browser():
    """The Pleiades 2017 DIMAP scene on its DEM (shareloc): the ground mesh vertices lie on the DEM
    terrain (bilinear heights of the resampled grid), at one node per DEM cell up to 129 per side."""
    from explorer.sources import load_source
    from tests.real.conftest import DEM_DIR, PHR_2017

    scene = load_source("dimap", str(PHR_2017), dem=str(DEM_DIR / "MNT_P1BP--2017030824934340CP.tif"),
                        dem_datum="egm96").scene
    n, cells = B.ground_mesh_nodes(scene)
    fp = scene.footprint()
    span = max(np.ptp(fp[:, 0]), np.ptp(fp[:, 1]))
    assert cells == int(np.ceil(span / scene.terrain.dx)) and n == min(max(cells + 1, 41), 129)
    verts, faces = B.footprint_mesh(scene, n)
    assert verts.shape == (n * n, 3) and faces.shape == (2 * (n - 1) ** 2, 3)
    np.testing.assert_allclose(verts[:, 2], scene.terrain.height(verts[:, 0], verts[:, 1]), atol=1e-3)
    assert np.ptp(verts[:, 2]) > 30.0  # the coastal relief is there
    flat = build_scene("WSU")
    assert B.ground_mesh_nodes(flat) == (41, None)


def test_automatic_height_exaggeration_makes_the_relief_visible():
    """Issue 24: a real DEM's relief (tens of metres under a footprint of tens of km) is exaggerated to about
    5 % of the footprint diagonal, rounded down to a nice factor; flat terrain stays at 1."""
    from explorer.presets import build_scene
    from explorer.scene3d.builders import NICE_FACTORS, RELIEF_SHARE, auto_height_exaggeration

    assert auto_height_exaggeration(build_scene("WSU")) == (1.0, 0.0)
    scene = build_scene("ISB", relief_m=50.0)
    factor, relief = auto_height_exaggeration(scene)
    fp = scene.footprint()
    diag = max(np.linalg.norm(fp[2] - fp[0]), np.linalg.norm(fp[3] - fp[1]))
    assert relief == scene.terrain.max_height - scene.terrain.min_height
    want = RELIEF_SHARE * diag / relief
    assert factor in NICE_FACTORS and factor <= want and (factor == NICE_FACTORS[-1] or
                                                           NICE_FACTORS[NICE_FACTORS.index(factor) + 1] > want)
