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
    mesh = planes["/scanlines/planes"]
    assert mesh.faces.shape == (4, 3) and mesh.opacity < 1 and mesh.side == "double"
    assert planes["/scanlines/edges"].points.shape == (12, 2, 3)
    assert sorted(k for k in planes if "labels" in k) == [f"/scanlines/labels/{i}" for i in range(3)]
    np.testing.assert_allclose(mesh.vertices[0], f.sensor(scene.exterior.position(scene.scanline_time(rows[:1])))[0],
                               atol=1e-5)


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
