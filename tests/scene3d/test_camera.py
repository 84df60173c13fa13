"""Framing the 3D view (issue 24): the projection through viser's camera model against closed forms, and the
footprint filling at least half of the view for presets, a DEM scene and a CSM camera, in canvases of several
shapes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from explorer.presets import build_scene
from explorer.scene3d import builders as B
from explorer.scene3d.camera import (
    DEFAULT_ASPECT,
    FOOTPRINT_FILL,
    VIEW_FOV_Y,
    VIEW_MARGIN,
    footprint_share,
    frame_footprint,
    view_ndc,
)

DATA = Path(__file__).resolve().parents[1] / "data"
ASPECTS = (DEFAULT_ASPECT, 1032 / 1080, 16 / 9, 0.35)


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("turn", [0.0, 0.7, 2.9])
def test_projection_is_the_pinhole_of_a_vertical_field_of_view(turn):
    """A camera 10 km south of the origin looking north, +z up: a point (x, 0, z) is at x / (10 tan(fov/2)
    aspect), z / (10 tan(fov/2)) in the view -- whichever way the whole configuration is turned about z."""
    t, aspect = np.tan(VIEW_FOV_Y / 2), 0.6
    pts = np.array([[0.0, 0.0, 0.0], [10 * t * aspect, 0.0, 0.0], [0.0, 0.0, 10 * t], [-2.0, 0.0, 3.0],
                    [1.0, 5.0, 1.0]])
    want = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-2 / (10 * t * aspect), 3 / (10 * t)],
                     [1 / (15 * t * aspect), 1 / (15 * t)]])
    r = _rot_z(turn)
    ndc, depth = view_ndc(pts @ r.T, r @ [0.0, -10.0, 0.0], np.zeros(3), fov_y=VIEW_FOV_Y, aspect=aspect)
    np.testing.assert_allclose(ndc, want, atol=1e-12)
    np.testing.assert_allclose(depth, [10, 10, 10, 10, 15], atol=1e-12)


def _footprint_and_track(scene, exaggeration: float = 1.0):
    frame = B.DisplayFrame.for_scene(scene, height_exaggeration=exaggeration)
    outline = frame.ground(B.footprint_outline(scene, per_edge=16).reshape(-1, 3))
    _, pos = B.track_positions(scene, 9)
    corners = frame.ground(np.asarray(scene.footprint(), dtype=np.float64))
    return frame, outline, frame.sensor(pos), corners


def _assert_framed(outline, track, corners, aspect):
    pose = frame_footprint(outline, track, aspect=aspect)
    ndc, depth = view_ndc(corners, pose.position, pose.look_at, fov_y=pose.fov_y, aspect=aspect)
    assert np.all(depth > 0)
    assert np.all(np.abs(ndc) <= VIEW_MARGIN + 1e-9)  # every corner in the view, room for labels
    width, height = footprint_share(outline, pose)
    assert max(width, height) == pytest.approx(FOOTPRINT_FILL, abs=1e-6)  # the binding axis
    assert max(width, height) >= 0.5 and min(width, height) > 0.1  # seen obliquely, not edge-on
    # the corners alone (the measure) fill at least half of the view too
    assert max(*footprint_share(corners, pose)) >= 0.5
    return pose


@pytest.mark.parametrize("aspect", ASPECTS)
@pytest.mark.parametrize("preset", ["WSU", "ISB"])
def test_the_footprint_fills_the_view_of_any_canvas(preset, aspect):
    scene = build_scene(preset)
    frame, outline, track, corners = _footprint_and_track(scene)
    pose = _assert_framed(outline, track, corners, aspect)
    # the camera looks from the right of the flight, above the horizon, and far enough to hold the near plane
    assert pose.position[2] > pose.look_at[2] and pose.near < 0.01 * np.linalg.norm(pose.position - pose.look_at)


def test_relief_exaggerated_footprint_is_framed_with_its_heights():
    scene = build_scene("WSU", relief_m=800.0, relief_seed=2)
    factor, _ = B.auto_height_exaggeration(scene)
    _, outline, track, _ = _footprint_and_track(scene, factor)
    corners = outline  # on a DEM the outline's heights matter: all of it is inside
    _assert_framed(outline, track, corners, DEFAULT_ASPECT)


@pytest.mark.parametrize("aspect", [DEFAULT_ASPECT, 16 / 9])
def test_a_csm_camera_footprint_is_framed(aspect):
    from explorer.sources import load_source

    src = load_source("isd", str(DATA / "usgscsm" / "orbitalLineScan.json"))
    _, outline, track, corners = _footprint_and_track(src.scene)
    _assert_framed(outline, track, corners, aspect)


def test_framing_refuses_impossible_requests():
    g = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    t = np.array([[0.0, -1, 5], [0, 2, 5]])
    with pytest.raises(ValueError, match="fill"):
        frame_footprint(g, t, fill=0.99, margin=0.9)
    with pytest.raises(ValueError, match="aspect"):
        frame_footprint(g, t, aspect=0.0)
