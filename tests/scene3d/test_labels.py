"""3D labels never clipped by the view's edge nor stacked (issue 24): the layout against boxes computed from
the anchors' definition, and the explorer's labels in its framed view."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.scene3d.camera import VIEW_FOV_Y, view_ndc
from explorer.scene3d.labels import GAP_PX, Label, box_at, boxes_overlap, label_box_px, place_labels

W, H = 512.0, 900.0
CAM, LOOK = np.array([0.0, -10.0, 0.0]), np.zeros(3)


def _at_px(x: float, y: float) -> np.ndarray:
    """The 3D point (on the plane y = 0) that the camera above sees at pixel (x, y)."""
    t = np.tan(VIEW_FOV_Y / 2)
    u, v = 2 * x / W - 1, 1 - 2 * y / H
    return np.array([10 * t * (W / H) * u, 0.0, 10 * t * v])


def test_anchor_boxes_follow_vipers_definition():
    size = label_box_px("abc")
    assert box_at(np.array([100.0, 50.0]), size, "top-left").tolist() == [100, 50, 100 + size[0], 50 + size[1]]
    assert box_at(np.array([100.0, 50.0]), size, "center-right").tolist() == pytest.approx(
        [100 - size[0], 50 - size[1] / 2, 100, 50 + size[1] / 2])
    assert label_box_px("abcdef")[0] > label_box_px("abc")[0] and label_box_px("a", 2.0)[1] > size[1]


def test_pixels_of_the_helper_points():
    ndc, _ = view_ndc(np.array([_at_px(0, 0), _at_px(W, H)]), CAM, LOOK, aspect=W / H)
    np.testing.assert_allclose(ndc, [[-1, 1], [1, -1]], atol=1e-12)


def test_labels_at_one_point_are_not_stacked():
    """viser puts a label beside its point (touching it) or centred above / below it: two labels of one point
    always touch there, so the first (priority) is drawn and the others are hidden, never stacked."""
    p = _at_px(256, 450)
    labels = [Label(f"/l{k}", f"label number {k}", p, ("center-left",)) for k in range(4)]
    out = place_labels(labels, CAM, LOOK, fov_y=VIEW_FOV_Y, width=W, height=H)
    assert out["/l0"][0] == "center-left" and [out[f"/l{k}"] for k in (1, 2, 3)] == [None] * 3
    # a little apart, the second turns to the free side instead of covering the first
    labels = [Label("/a", "label number 0", _at_px(256, 450), ("center-left",)),
              Label("/b", "label number 1", _at_px(250, 464), ("center-left",))]
    out = place_labels(labels, CAM, LOOK, fov_y=VIEW_FOV_Y, width=W, height=H)
    assert out["/a"][0] == "center-left" and out["/b"][0] == "center-right"
    assert not boxes_overlap(out["/a"][1], out["/b"][1], GAP_PX)


def test_a_label_at_the_edge_turns_inwards_and_one_outside_is_hidden():
    right = Label("/r", "a long label near the right edge", _at_px(W - 5, 300), ("center-left",))
    bottom = Label("/b", "bottom", _at_px(200, H - 3), ("top-left",))
    out_of_view = Label("/o", "outside", _at_px(W + 40, 300))
    out = place_labels([right, bottom, out_of_view], CAM, LOOK, fov_y=VIEW_FOV_Y, width=W, height=H)
    assert out["/r"][0].endswith("right") and out["/r"][1][2] <= W - GAP_PX  # text runs to the left
    assert out["/b"][0].startswith("bottom") and out["/b"][1][3] <= H - GAP_PX
    assert out["/o"] is None


def test_a_label_that_fits_nowhere_is_hidden_not_stacked():
    p = _at_px(256, 450)
    wide = "x" * 120  # wider than the view on either side of its point
    out = place_labels([Label("/w", wide, p)], CAM, LOOK, fov_y=VIEW_FOV_Y, width=W, height=H)
    assert out["/w"] is None


def test_a_label_moves_to_its_alternative_point_so_that_both_show():
    """One by one, the first label would take the shared point and hide the second; the search moves the first to
    its alternative point so both are shown."""
    p, q = _at_px(200, 450), _at_px(200, 200)
    labels = [Label("/first", "first label", p, ("center-left",), alternatives=(q,)),
              Label("/second", "second label", p, ("center-left",))]
    out = place_labels(labels, CAM, LOOK, fov_y=VIEW_FOV_Y, width=W, height=H)
    assert out["/first"] is not None and out["/second"] is not None
    np.testing.assert_allclose(out["/first"][2], q) and np.testing.assert_allclose(out["/second"][2], p)
    assert not boxes_overlap(out["/first"][1], out["/second"][1], GAP_PX)
