"""3D labels never clipped by the view's edge nor stacked (issue 24): the layout against boxes computed from
the anchors' definition, and the explorer's labels in its framed view."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.scene3d.camera import VIEW_FOV_Y, view_ndc
from explorer.scene3d.labels import (
    GAP_PX,
    Label,
    View,
    box_at,
    boxes_overlap,
    label_box_px,
    place_labels,
    place_labels_in_views,
)

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


def test_labels_laid_out_for_two_window_shapes_fit_both():
    """One layout for a tall (512 x 900) and a wide (1400 x 500) canvas seen from the same camera: a label that
    fits the wide view to the right of its point but would leave the tall one turns to the left, one
    outside the tall view is hidden, and two that clash only in the wide view are not both shown; each box is
    the anchor's box (:func:`box_at`) at the point's pixel in that view (computed here from the field of view)."""
    tall = View(CAM, LOOK, VIEW_FOV_Y, W, H)
    wide = View(CAM, LOOK, VIEW_FOV_Y, 1400.0, 500.0)

    def px(view: View, p: np.ndarray) -> np.ndarray:  # pinhole: the camera looks along +y, z up
        f = (view.height / 2) / np.tan(view.fov_y / 2)
        return np.array([view.width / 2 + f * p[0] / 10.0, view.height / 2 - f * p[2] / 10.0])

    near_right = Label("/r", "a label near the tall view's right edge", _at_px(W - 20, 300), ("center-left",))
    outside_tall = Label("/o", "outside the tall view", _at_px(W + 60, 450))
    out = place_labels_in_views([near_right, outside_tall], [tall, wide])
    anchor, boxes, point = out["/r"]
    assert anchor.endswith("right") and boxes.shape == (2, 4)
    size = label_box_px(near_right.text)
    for view, box in zip((tall, wide), boxes, strict=True):
        np.testing.assert_allclose(box, box_at(px(view, point), size, anchor), atol=1e-9)
        assert box[0] >= GAP_PX and box[2] <= view.width - GAP_PX
    assert out["/o"] is None
    # alone in the wide view it keeps its preferred side, and the one outside the tall view is shown
    alone = place_labels_in_views([near_right, outside_tall], [wide])
    assert alone["/r"][0] == "center-left" and alone["/o"] is not None
    # in the tall view the scale is 900 / 500 = 1.8 times the wide one's: labels apart there may clash in the
    # wide one
    a = Label("/a", "first label", _at_px(256, 450), ("center-left",))
    b = Label("/b", "second label", _at_px(256, 450 + 1.3 * label_box_px("x")[1]), ("center-left",))
    only_tall = place_labels_in_views([a, b], [tall])
    assert all(v is not None and v[0] == "center-left" for v in only_tall.values())
    in_wide = [box_at(px(wide, lab.point), label_box_px(lab.text), "center-left") for lab in (a, b)]
    assert boxes_overlap(in_wide[0], in_wide[1], GAP_PX)  # the tall view's layout would stack them in the wide
    both = place_labels_in_views([a, b], [tall, wide])
    shown = [k for k, v in both.items() if v is not None]
    assert "/a" in shown
    for i in range(2):
        boxes_shown = [both[k][1][i] for k in shown]
        for j in range(len(boxes_shown)):
            for k in range(j + 1, len(boxes_shown)):
                assert not boxes_overlap(boxes_shown[j], boxes_shown[k], GAP_PX)
