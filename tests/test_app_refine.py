"""The explorer's Refinement folder: live re-adjustment when the model or the dropped points change."""

from __future__ import annotations

import pytest

pytest.importorskip("torch")
viser = pytest.importorskip("viser")

from explorer.app.refine_view import RefineView  # noqa: E402
from tests.refine.cases import pleiades, simulate_points  # noqa: E402


@pytest.fixture
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=8181, verbose=False)
    yield srv
    srv.stop()


def test_refine_folder_readjusts_live(server):
    rpc = pleiades()
    control = simulate_points(rpc, 12, seed=1, prefix="g")
    view = RefineView(server.gui, rpc, control, simulate_points(rpc, 30, seed=2, prefix="c"), sigma_px=0.3)
    assert view.error is None and view.refinement.model == "affine"
    assert len(view.quiver.figure.data) > 0 and "affine" in view.summary.content
    view.model.value = "shift"
    view.update()
    assert view.refinement.model == "shift" and len(view.refinement.parameters) == 2
    view.drop.value = "g0, g5"
    view.update()
    assert view.refinement.result.outlier.size == 10
    ids = {r["id"] for r in view.refinement.points_rows() if r["role"] == "control"}
    assert "g0" not in ids and "g5" not in ids
    view.model.value = "poly2"
    view.update()  # poly2 on 10 points (the GUI's own change runs in the background; this one now)
    assert view.refinement.model == "poly2"
    view.drop.value = ",".join(f"g{i}" for i in range(7))  # 5 points left for 12 parameters
    view.update()
    assert view.error.startswith("too few control points") and "Not adjusted" in view.summary.content
    view.drop.value = "nope"
    view.update()
    assert view.error == "no control point nope"
    assert view.refinement.model == "poly2"  # the last good adjustment (poly2 on 10 points) stays shown


def _scene_control(scene, true, n=20, seed=5, noise_px=0.0):
    import numpy as np

    from explorer.refine.points_io import PointTable
    from explorer.refine.torch_scene import adjusted_scene

    rng = np.random.default_rng(seed)
    g = scene.image_to_ground(rng.uniform(0.05, 0.95, n) * scene.n_rows, rng.uniform(0.05, 0.95, n) * scene.n_columns,
                              height=rng.uniform(-200, 200, n))
    row, col = adjusted_scene(scene, "attitude", true).ground_to_image(g)
    lon, lat, h = scene.frame.enu_to_geodetic(g)
    return PointTable([f"g{i}" for i in range(n)], row + rng.normal(0, noise_px, n), col + rng.normal(0, noise_px, n),
                      lon, lat, h)


def test_scene_refinement_draws_both_trajectories_in_3d_and_redraws_them_live(server):
    import numpy as np

    from explorer.presets import build_scene
    from explorer.refine.trajectory import refinement_trajectory
    from explorer.scene3d.builders import DisplayFrame

    scene = build_scene("WSU")
    true = np.array([30.0, -20.0, 10.0, 2e-5, -1e-5, 1e-5])
    frame = DisplayFrame.for_scene(scene)
    view = RefineView(server.gui, scene, _scene_control(scene, true, noise_px=0.3), sigma_px=0.3,
                      scene_api=server.scene, display_frame=lambda: frame)
    assert view.error is None and view.models == ["attitude", "attitude-drift"]
    assert set(view._nodes) >= {"/refine/original/track", "/refine/adjusted/track", "/refine/adjusted/attitude"}
    params = {p["name"]: p["value"] for p in view.refinement.report()["parameters"]}
    d = np.linalg.norm([params["position_e_m"], params["position_n_m"], params["position_u_m"]])
    assert view.trajectory_3d["displacement_m"] == pytest.approx([d, d], rel=1e-9)  # the view's number = report's
    kp = view.trajectory_3d["position_factor"]
    assert f"drawn x{kp:g}" in view.trajectory_text.content
    drawn = np.asarray(view._nodes["/refine/adjusted/track"].points)
    comp = refinement_trajectory(view.refinement)
    np.testing.assert_allclose(drawn[:, 0], frame.sensor(comp.original_centre_m + kp * comp.displacement_m)[:-1],
                               atol=1e-5)  # (viser keeps float32)
    before = view.refinement.parameters.copy()
    view.drop.value = "g0, g3, g7"
    view.update()
    assert view.refinement.result.outlier.size == 17
    assert np.abs(view.refinement.parameters - before).max() > 0  # dropping points re-adjusts
    params2 = {p["name"]: p["value"] for p in view.refinement.report()["parameters"]}
    d2 = np.linalg.norm([params2["position_e_m"], params2["position_n_m"], params2["position_u_m"]])
    assert view.trajectory_3d["displacement_m"] == pytest.approx([d2, d2], rel=1e-9)  # and redraws the 3D
    view.model.value = "attitude-drift"
    view.update()
    assert len(view.refinement.parameters) == 12 and "attitude-drift" in view.summary.content
    view.draw_3d(visible=False)  # another scene shown: hidden
    assert not any(h.visible for h in view._nodes.values())


def test_every_source_kind_has_a_refinement_target(monkeypatch):
    from explorer.app.refine_view import refine_target_of
    from explorer.refine import target as target_module
    from explorer.refine.images import image_adapter
    from explorer.sources import load_source
    from tests.refine.cases import PLEIADES
    from tests.refine.test_target import ORBITAL, only_rpcs_and_mpc_scenes

    preset = refine_target_of(load_source("preset", "WSU"))
    assert not preset.is_stand_in and preset.label == "the Scene itself" and preset.model.n_rows > 0
    rpc = refine_target_of(load_source("rpc", str(PLEIADES)))
    assert not rpc.is_stand_in and "the RPC itself" in rpc.label
    isd = load_source("isd", str(ORBITAL))
    direct = refine_target_of(isd)  # the camera itself once it is refinable, else its stand-in
    image_adapter(direct.model)
    assert direct.label == ("the MPC fitted to the CSM camera (a stand-in)" if direct.is_stand_in
                            else "the CSM camera itself")
    monkeypatch.setattr(target_module, "_refinable", only_rpcs_and_mpc_scenes)  # the stand-in path
    target = refine_target_of(isd)
    assert target.is_stand_in and target.model is isd.stand_in.sensor and target.truth is isd.scene
    assert target.label == "the MPC fitted to the CSM camera (a stand-in)"


def test_the_apps_3d_view_redraws_the_trajectories_in_its_frame_and_hides_them_on_another_scene(server, tmp_path):
    """``explore --preset WSU --gcps``: the trajectories are drawn in the app's display frame (the original on the
    satellite track), redrawn when the frame changes (true sensor distance), hidden on another preset."""
    from argparse import Namespace

    import numpy as np

    from explorer.app.server import _refine_folder
    from explorer.presets import build_scene
    from explorer.refine.trajectory import refinement_trajectory
    from explorer.sources import load_source
    from tests.refine.cases import write_points_csv
    from tests.test_app import make_app, toy_registry

    scene = build_scene("WSU")
    gcps = write_points_csv(tmp_path / "g.csv", _scene_control(scene, np.array([30.0, -20.0, 10.0, 2e-5, -1e-5, 1e-5]),
                                                                noise_px=0.3))
    ready = _refine_folder(Namespace(gcps=str(gcps), check=None, sigma_px=0.3), load_source("preset", "WSU"))
    with toy_registry():
        app = make_app(server)
        ready(app)
        view = app.refine_view
        comp = refinement_trajectory(view.refinement)

        def drawn(frame):
            np.testing.assert_allclose(view._nodes["/refine/original/track"].points[:, 0],
                                       frame.sensor(comp.original_centre_m)[:-1], rtol=1e-6, atol=1e-6)

        drawn(app.frame)
        np.testing.assert_allclose(view._nodes["/refine/original/track"].points[0, 0],
                                   app.nodes["/orbit/track"].points[0], atol=1e-3)  # starts where the orbit does
        compressed = app.frame
        app.handles["distance"].value = "true"
        assert not app.frame.compressed and compressed.compressed
        drawn(app.frame)
        app.handles["preset"].value = "ISB"
        assert app.scene.name == "ISB" and not any(h.visible for h in view._nodes.values())
        app.handles["preset"].value = "WSU"
        # (at the true distance the label's points are far outside the framed view: the label layout hides it)
        assert all(h.visible for k, h in view._nodes.items() if k != "/refine/label")
        assert view._nodes["/refine/label"].visible == (app.label_layout["/refine/label"] is not None)
        drawn(app.frame)


EXPORT_REFUSED = ("--gcps refines live in the explorer and is not part of --export; write the refinement's files "
                  "with 'pushbroom refine SOURCE --gcps FILE --out DIR' (report.json, points.csv, panels.html)")
PAIR_REFUSED = ("--gcps refines one image, not a --pair (adjust a pair to tie points with "
                "'pushbroom refine --images A B --ties ties.csv')")


@pytest.mark.parametrize("extra, message", [(["--preset", "WSU", "--export", "OUT"], EXPORT_REFUSED),
                                            (["--pair", "A", "B"], PAIR_REFUSED)])
def test_explore_gcps_options_that_would_be_ignored_are_refused(tmp_path, capsys, extra, message):
    from explorer.cli import main

    extra = [str(tmp_path / "out") if e == "OUT" else e for e in extra]
    assert main(["explore", "--gcps", str(tmp_path / "g.csv"), *extra]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(message)
    assert not (tmp_path / "out").exists()


def test_explore_check_without_gcps_is_refused(tmp_path, capsys):
    from explorer.cli import main

    assert main(["explore", "--preset", "WSU", "--check", str(tmp_path / "c.csv"), "--port", "8185"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(
        "--check goes with --gcps (the check points of the refinement)")


def test_a_csm_camera_is_refined_live_with_its_trajectory(server):
    """``explore --isd --gcps``: the CSM camera itself (usgscsm's orbital test camera) adjusted by a known roll;
    the folder's 3D trajectory turns by the angle of the fitted roll, pitch and yaw, and does not move."""
    import numpy as np

    from explorer.app.refine_view import refine_target_of
    from explorer.geometry.rotations import rotation_from_opk
    from explorer.refine.line_adjust import adjusted_sensor, correction_for
    from explorer.refine.points_io import PointTable
    from explorer.refine.trajectory import rotation_angle
    from explorer.scene3d.builders import DisplayFrame
    from explorer.sources import load_source
    from tests.refine.test_target import ORBITAL

    source = load_source("isd", str(ORBITAL))
    target = refine_target_of(source)
    camera = source.scene
    assert not target.is_stand_in and target.model is camera
    truth = adjusted_sensor(camera, correction_for(camera, "attitude"), np.array([2e-3, -1e-3, 0.0]))
    rng = np.random.default_rng(4)
    r, c = rng.uniform(1, camera.n_rows - 2, 12), rng.uniform(1, camera.n_columns - 2, 12)
    g = truth.image_to_ground(r, c)
    lon, lat, h = camera.frame.enu_to_geodetic(g)
    control = PointTable([f"g{i}" for i in range(12)], r + rng.normal(0, 0.05, 12), c + rng.normal(0, 0.05, 12),
                         lon, lat, h)
    frame = DisplayFrame.for_scene(camera)
    view = RefineView(server.gui, target, control, sigma_px=0.05, scene_api=server.scene, display_frame=lambda: frame)
    assert view.error is None and view.has_trajectory and view.refinement.model == "attitude"
    assert view.what.content == "Adjusting **the CSM camera itself**."
    p = {q["name"]: q["value"] for q in view.refinement.report()["parameters"]}
    turn = rotation_angle(rotation_from_opk(*(np.array([p[k]]) for k in ("roll_rad", "pitch_rad", "yaw_rad"))))[0]
    assert view.trajectory_3d["attitude_change_urad"] == pytest.approx([turn * 1e6] * 2, rel=1e-6)
    assert view.trajectory_3d["displacement_m"] == pytest.approx([0.0, 0.0], abs=1e-6)
    sigma = np.array([q["sigma"] for q in view.refinement.report()["parameters"]])
    assert np.all(np.abs(view.refinement.parameters - np.array([2e-3, -1e-3, 0.0])) < 3 * sigma), (
        view.refinement.parameters, sigma)  # roll, pitch to ~3e-5 rad; yaw is loose on a 16 x 16 px image
    view.drop.value = "g0"
    view.update()
    assert view.error is None and view.refinement.result.outlier.size == 11


def test_gui_changes_readjust_in_the_background_and_the_newest_change_wins(server, monkeypatch):
    import explorer.refine.adjust as adjust

    rpc = pleiades()
    view = RefineView(server.gui, rpc, simulate_points(rpc, 12, seed=1, prefix="g"), sigma_px=0.3)
    calls = []
    real = adjust.refine_images
    monkeypatch.setattr(adjust, "refine_images", lambda *a, **k: calls.append(k["model"]) or real(*a, **k))
    with view._run_lock:  # an adjustment is running: the GUI changes queue behind it
        view.model.value = "shift"  # (a GUI change: the handle's callback)
        first = view.thread
        assert view.summary.content == "*Re-adjusting (shift, 0 point(s) dropped) ...*"
        view.model.value = "poly2"
        second = view.thread
    first.join(60)
    second.join(60)
    assert calls == ["poly2"]  # the superseded change never adjusted
    assert view.refinement.model == "poly2" and view.summary.content.startswith("**poly2**")
    view.drop.value = "nope"
    view.thread.join(60)
    assert view.error == "no control point nope" and view.refinement.model == "poly2"


@pytest.mark.parametrize("preset", ["WSU", "agile"])
def test_the_default_view_holds_the_trajectories_and_their_label(server, tmp_path, preset):
    """Issue 28: with ``--gcps`` the framed default view holds both trajectories (every drawn point of the tracks
    inside the view, closed-form projection through viser's camera model) with the footprint still at least half
    of it; the sensor side is drawn nearer (a stated compressed distance) instead; the trajectories' label is laid
    out with the others (inside the view, clear of every other label); without --gcps the default distance."""
    from argparse import Namespace

    import numpy as np

    from explorer.app.server import _refine_folder
    from explorer.presets import build_scene
    from explorer.scene3d.builders import COMPRESSED_DISTANCE_FACTOR
    from explorer.scene3d.camera import DEFAULT_ASPECT, DEFAULT_CANVAS_PX, VIEW_FOV_Y, footprint_share, view_ndc
    from explorer.scene3d.labels import boxes_overlap
    from explorer.sources import load_source
    from tests.refine.cases import write_points_csv
    from tests.test_app import make_app, toy_registry

    scene = build_scene(preset)
    gcps = write_points_csv(tmp_path / "g.csv", _scene_control(scene, np.array([30.0, -20.0, 10.0, 2e-5, -1e-5, 1e-5]),
                                                                noise_px=0.3))
    ready = _refine_folder(Namespace(gcps=str(gcps), check=None, sigma_px=0.3), load_source("preset", preset))
    with toy_registry():
        app = make_app(server, preset=preset)
        diagonal = app.frame.diagonal_km
        track_km = float(np.linalg.norm(app.nodes["/orbit/track"].points.mean(axis=0)))
        assert track_km == pytest.approx(COMPRESSED_DISTANCE_FACTOR * diagonal, rel=0.02)  # no refinement: default
        pos, look, _ = app.camera_pose
        drawn = np.asarray(app.nodes["/orbit/track"].points, dtype=np.float64)
        ndc, _ = view_ndc(drawn, np.array(pos), np.array(look))
        assert np.abs(ndc).max() > 1.0  # (the problem: the track above the framed view)
        ready(app)
        view = app.refine_view
        assert app._framing[2] is not None
        pos, look, _ = app.camera_pose
        for key in ("/refine/original/track", "/refine/adjusted/track"):
            pts = np.asarray(view._nodes[key].points, dtype=np.float64).reshape(-1, 3)
            ndc, depth = view_ndc(pts, np.array(pos), np.array(look), fov_y=VIEW_FOV_Y, aspect=DEFAULT_ASPECT)
            assert np.all(depth > 0) and np.abs(ndc).max() <= 0.85 + 1e-9, (key, np.abs(ndc).max())
        corners = app.frame.ground(np.asarray(app.scene.footprint(), dtype=np.float64))
        ndc, depth = view_ndc(corners, np.array(pos), np.array(look))
        assert np.all(depth > 0) and np.abs(ndc).max() < 1.0

        class Pose:
            position, look_at, fov_y, aspect = np.array(pos), np.array(look), VIEW_FOV_Y, DEFAULT_ASPECT

        assert max(footprint_share(corners, Pose)) >= 0.5 - 1e-9
        # the sensor side drawn nearer, stated with the true distance
        shown_km = view.trajectory_3d["display_distance_km"]
        assert shown_km < COMPRESSED_DISTANCE_FACTOR * diagonal and view.trajectory_3d["true_distance_km"] > 400
        assert f"drawn {shown_km:.3g} km from the scene centre" in view.trajectory_text.content
        # the label: laid out, inside the default canvas, clear of every other label shown
        placed = app.label_layout["/refine/label"]
        assert placed is not None and view._nodes["/refine/label"].visible
        assert view._nodes["/refine/label"].anchor == placed[0]
        box = placed[1]
        w, h = DEFAULT_CANVAS_PX
        assert box[0] >= 0 and box[1] >= 0 and box[2] <= w and box[3] <= h
        others = [v[1] for k, v in app.label_layout.items() if v is not None and k != "/refine/label"]
        assert others and not any(boxes_overlap(box, o) for o in others)
        # a re-adjustment redraws the label (a new node): it is laid out again
        old = view._nodes["/refine/label"]
        view.drop.value = "g0"
        view.update()
        assert view._nodes["/refine/label"] is not old
        assert app.label_layout["/refine/label"] is not None
        assert view._nodes["/refine/label"].anchor == app.label_layout["/refine/label"][0]
