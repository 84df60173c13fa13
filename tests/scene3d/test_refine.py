"""The 3D trajectories of a refinement: the drawn adjusted track is the original plus the stated factor times the
displacement (closed form of a known correction), the triads are the camera axes, the label states the factors."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.presets import build_scene
from explorer.refine.trajectory import trajectory_comparison
from explorer.scene3d.builders import DisplayFrame
from explorer.scene3d.refine import add_refined_trajectories, auto_factors, nice_factor, triad_segments

pytest.importorskip("torch")
from explorer.refine.torch_scene import adjusted_scene  # noqa: E402


class _Handle:
    def __init__(self, kind, name, args, kwargs):
        self.kind, self.name, self.args, self.kwargs = kind, name, args, kwargs
        self.visible = True


class RecordingScene:
    """Stands in for viser's SceneApi: records the nodes added."""

    def __init__(self):
        self.nodes = {}

    def __getattr__(self, kind):
        def add(name, *args, **kwargs):
            self.nodes[name] = _Handle(kind, name, args, kwargs)
            return self.nodes[name]
        return add


def test_nice_factor():
    assert [nice_factor(w) for w in (0.3, 1.0, 1.9, 4.99, 7.0, 20.0, 3.3e4, np.inf)] == [1, 1, 1, 2, 5, 20, 2e4, 1]


def test_triad_segments_are_the_camera_axes():
    rot = np.stack([np.eye(3), np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])])
    seg = triad_segments(np.array([[0.0, 0, 0], [1.0, 2, 3]]), rot, 2.0)
    assert seg.shape == (6, 2, 3)
    np.testing.assert_allclose(seg[:3, 1], 2.0 * np.eye(3))
    np.testing.assert_allclose(seg[3:, 1] - seg[3:, 0], 2.0 * rot[1].T)  # x axis = first column of R
    np.testing.assert_allclose(seg[3:, 0], np.tile([1.0, 2, 3], (3, 1)))


@pytest.mark.parametrize("distance", ["compressed", "true"])
def test_drawn_tracks_and_stated_factors(distance):
    scene = build_scene("WSU")
    p = np.array([30.0, -40.0, 0.0, 2e-6, 0.0, 0.0])  # 50 m and 2 urad: a closed-form displacement and turn
    comp = trajectory_comparison(scene, adjusted_scene(scene, "attitude", p), n=11)
    frame = DisplayFrame.for_scene(scene, sensor_distance=distance)
    kp, ka = auto_factors(comp, frame)
    assert kp == nice_factor(0.1 * frame.diagonal_km * 1e3 / 50.0) and ka == nice_factor(0.2 / 2e-6) == 1e5
    api = RecordingScene()
    nodes, info = add_refined_trajectories(api, comp, frame)
    assert set(nodes) == {"/refine/original/track", "/refine/adjusted/track", "/refine/original/attitude",
                          "/refine/adjusted/attitude", "/refine/label"}
    orig = nodes["/refine/original/track"].args[0]
    adj = nodes["/refine/adjusted/track"].args[0]
    # the original lies on the orbit as add_orbit draws it; the adjusted is kp x 50 m = kp x 0.05 km away
    np.testing.assert_allclose(orig[:, 0], frame.sensor(comp.original_centre_m[:-1]), atol=1e-12)
    np.testing.assert_allclose(adj - orig, np.broadcast_to(kp * np.array([0.03, -0.04, 0.0]), adj.shape), atol=1e-9)
    # the adjusted triads turned by ka x 2 urad about the same axis
    tri_o = nodes["/refine/original/attitude"].args[0]
    tri_a = nodes["/refine/adjusted/attitude"].args[0]
    axes_o = (tri_o[:, 1] - tri_o[:, 0]).reshape(-1, 3, 3)
    axes_a = (tri_a[:, 1] - tri_a[:, 0]).reshape(-1, 3, 3)
    a = ka * 2e-6  # an omega offset turns the camera about the ENU east axis: R_x(w + d) R_x(w)^T = R_x(d)
    rx = np.array([[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    np.testing.assert_allclose(axes_a, axes_o @ rx.T, atol=1e-12 * frame.diagonal_km)
    assert not np.allclose(axes_a, axes_o, atol=1e-3 * frame.diagonal_km)  # visibly turned
    assert f"drawn x{kp:g}" in info["text"] and f"drawn x{ka:g}" in info["text"] and "50 m" in info["text"]
    want = f"adjusted trajectory (red): position x{kp:g}, attitude x{ka:g}"
    assert nodes["/refine/label"].args[0] == info["label"] == want
    assert info["displacement_m"] == pytest.approx([50.0, 50.0])
    fixed, info2 = add_refined_trajectories(RecordingScene(), comp, frame, position_factor=1.0, attitude_factor=1.0)
    np.testing.assert_allclose(fixed["/refine/adjusted/track"].args[0] - orig,
                               np.broadcast_to([0.03, -0.04, 0.0], adj.shape), atol=1e-9)
    assert "drawn x1;" in info2["text"]
