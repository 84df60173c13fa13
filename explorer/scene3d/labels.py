"""Placing the 3D view's text labels so that none is clipped by the view's edge or stacked on another.

viser draws a label as screen-sized text beside its 3D point, on the side its ``anchor`` names
(``"center-right"``: the label's right-centre is at the point, so the text runs to the left).  Given the
camera pose the view is framed with (:mod:`explorer.scene3d.camera`), :func:`place_labels` projects each
label's point, estimates its box in pixels (:func:`label_box_px`; measured in Chromium: 5.3 px per
character and 12 px of text at ``font_screen_scale=1``, plus the label's padding) and gives each label an
anchor whose box lies inside the view and clear of every other shown label's (the most labels shown, the
earlier ones of a priority order first, each on the side nearest its preference; a label may also stand at
one of its alternative points).  A label whose points are outside the view, or that fits nowhere beside the
others, is hidden -- never drawn half outside or over another.  Pure numpy (no viser).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from explorer.scene3d.camera import view_ndc

CHAR_PX = 5.6
"""Width of one character of a label at ``font_screen_scale=1``, pixels (measured: 5.0-5.4; rounded up)."""
TEXT_PX = 14.0
"""Height of a label's text line, pixels (measured: 12 with descenders; rounded up)."""
PAD_PX = 4.0
"""Padding added on every side of a label's text (its background box)."""
GAP_PX = 2.0
"""Free pixels kept between two labels and between a label and the view's edge."""

ANCHOR_OFFSET: dict[str, tuple[float, float]] = {
    "top-left": (0.0, 0.0), "top-center": (-0.5, 0.0), "top-right": (-1.0, 0.0),
    "center-left": (0.0, -0.5), "center-center": (-0.5, -0.5), "center-right": (-1.0, -0.5),
    "bottom-left": (0.0, -1.0), "bottom-center": (-0.5, -1.0), "bottom-right": (-1.0, -1.0),
}
"""Box origin relative to the label's point, in box widths / heights (x right, y down), per viser anchor."""
FALLBACK_ANCHORS = ("center-left", "center-right", "bottom-left", "top-left", "bottom-right", "top-right",
                    "bottom-center", "top-center")
"""Anchors tried after a label's own preferences, in this order."""


@dataclass(frozen=True)
class Label:
    """A label to place.

    Attributes
    ----------
    key : str
        Its node name.
    text : str
    point : ndarray, shape (3,)
        Display km.
    anchors : tuple of str
        Preferred anchors, best first (then :data:`FALLBACK_ANCHORS`).
    scale : float
        viser's ``font_screen_scale``.
    alternatives : tuple of ndarray (3,)
        Other points the label may stand at (for example the other end of a scanline), tried after
        ``point``.
    """

    key: str
    text: str
    point: np.ndarray
    anchors: tuple[str, ...] = ("center-left",)
    scale: float = 1.0
    alternatives: tuple[np.ndarray, ...] = ()


def label_box_px(text: str, scale: float = 1.0) -> tuple[float, float]:
    """(width, height) in pixels of a label showing ``text`` (one line), padding included."""
    return CHAR_PX * scale * len(text) + 2 * PAD_PX, TEXT_PX * scale + 2 * PAD_PX


def box_at(point_px: np.ndarray, size: tuple[float, float], anchor: str) -> np.ndarray:
    """Box (x0, y0, x1, y1) in pixels (y down) of a label of ``size`` anchored at ``point_px``."""
    fx, fy = ANCHOR_OFFSET[anchor]
    x0, y0 = point_px[0] + fx * size[0], point_px[1] + fy * size[1]
    return np.array([x0, y0, x0 + size[0], y0 + size[1]])


def boxes_overlap(a: np.ndarray, b: np.ndarray, gap: float = 0.0) -> bool:
    """True when boxes (x0, y0, x1, y1) come closer than ``gap`` pixels on both axes."""
    return bool(a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap)


def project_px(points: np.ndarray, position: np.ndarray, look_at: np.ndarray, *, fov_y: float,
               width: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (N, 2) (x right, y down, origin top-left) and in-front flags (N,) of points."""
    ndc, depth = view_ndc(points, position, look_at, fov_y=fov_y, aspect=width / height)
    px = np.stack([(ndc[:, 0] + 1.0) * 0.5 * width, (1.0 - ndc[:, 1]) * 0.5 * height], axis=1)
    return px, depth > 0


@dataclass(frozen=True)
class View:
    """A framed view the labels must fit in: camera ``position`` and ``look_at`` (display km), vertical field
    of view ``fov_y`` (radians) and the canvas ``width`` x ``height`` (pixels)."""

    position: np.ndarray
    look_at: np.ndarray
    fov_y: float
    width: float
    height: float


def place_labels(labels: Sequence[Label], position: np.ndarray, look_at: np.ndarray, *, fov_y: float,
                 width: float, height: float, search_first: int = 7
                 ) -> dict[str, tuple[str, np.ndarray, np.ndarray] | None]:
    """An anchor for each label so that no two overlap and each lies wholly inside the view.

    Parameters
    ----------
    labels : sequence of Label
        In priority order (a later label yields to an earlier one).
    position, look_at : ndarray, shape (3,)
        The camera, display km.
    fov_y : float
        Vertical field of view, radians.
    width, height : float
        The view in pixels.
    search_first : int
        The first this many labels are placed together by a (bounded) search for the most shown; the later
        ones (minor labels: a search's iteration numbers) one by one where they still fit.

    Returns
    -------
    dict
        ``{key: (anchor, box (x0, y0, x1, y1) px, point (3,))}`` -- the point being the label's own or one
        of its alternatives --, or ``{key: None}`` for a label left out (its points are outside the view or
        behind the camera, or no anchor fits).
    """
    view = View(np.asarray(position, dtype=np.float64), np.asarray(look_at, dtype=np.float64), float(fov_y),
                float(width), float(height))
    placed = place_labels_in_views(labels, [view], search_first=search_first)
    return {k: None if v is None else (v[0], v[1][0], v[2]) for k, v in placed.items()}


def place_labels_in_views(labels: Sequence[Label], views: Sequence[View], *, search_first: int = 7
                          ) -> dict[str, tuple[str, np.ndarray, np.ndarray] | None]:
    """:func:`place_labels` for several views at once (browsers of different canvas shapes showing the same
    labels): each label gets one anchor and point that keep it inside *every* view and clear of every other
    shown label in every view.

    Returns
    -------
    dict
        ``{key: (anchor, boxes (V, 4) px -- one (x0, y0, x1, y1) per view --, point (3,))}`` or ``{key: None}``.
    """
    out: dict[str, tuple[str, np.ndarray, np.ndarray] | None] = {lab.key: None for lab in labels}
    if not labels or not views:
        return out
    g = GAP_PX
    options: list[list[tuple[int, str, np.ndarray, np.ndarray]]] = []  # per label: (rank, anchor, boxes, point)
    for lab in labels:
        opts: list[tuple[int, str, np.ndarray, np.ndarray]] = []
        cands = np.array([lab.point, *lab.alternatives], dtype=np.float64).reshape(-1, 3)
        size = label_box_px(lab.text, lab.scale)
        anchors = tuple(dict.fromkeys((*lab.anchors, *FALLBACK_ANCHORS)))
        projected = [project_px(cands, v.position, v.look_at, fov_y=v.fov_y, width=v.width, height=v.height)
                     for v in views]
        for k in range(len(cands)):
            if not all(front[k] and 0.0 <= px[k, 0] <= v.width and 0.0 <= px[k, 1] <= v.height
                       for (px, front), v in zip(projected, views, strict=True)):
                continue
            for rank, anchor in enumerate(anchors):
                boxes = np.array([box_at(px[k], size, anchor) for px, _ in projected])
                if all(b[0] >= g and b[1] >= g and b[2] <= v.width - g and b[3] <= v.height - g
                       for b, v in zip(boxes, views, strict=True)):
                    opts.append((k * len(anchors) + rank, anchor, boxes, cands[k]))
        opts.sort(key=lambda o: o[0])
        options.append(opts)

    def clash(a: np.ndarray, b: np.ndarray) -> bool:  # two labels' boxes overlap in some view
        return any(boxes_overlap(x, y, g) for x, y in zip(a, b, strict=True))

    # the most labels shown, earlier ones first, each as near its preferred side as may be: a depth-first
    # search over the anchors (a few labels, a few anchors each; bounded)
    n = min(len(labels), search_first)
    best: list = [None] * n
    best_score: tuple = (-1,)
    chosen: list = [None] * n
    picked: list[int | None] = [None] * n  # the index of chosen[i] in options[i]
    budget = [20_000]
    # which options of two searched labels clash (in some view), for every pair: the search looks them up instead
    # of comparing boxes at each of its up to 20,000 steps (the same comparisons as clash(), vectorised)
    stacks = [np.array([o[2] for o in opts], dtype=np.float64).reshape(len(opts), len(views), 4)
              for opts in options[:n]]

    def clash_table(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        x, y = a[:, None], b[None, :]
        return np.asarray(((x[..., 0] < y[..., 2] + g) & (y[..., 0] < x[..., 2] + g) & (x[..., 1] < y[..., 3] + g)
                           & (y[..., 1] < x[..., 3] + g)).any(axis=-1))

    table = {(j, i): clash_table(stacks[j], stacks[i]) for i in range(n) for j in range(i)}

    possible = [bool(o) for o in options[:n]]

    def search(i: int, count: int, rank: int) -> None:
        nonlocal best, best_score
        budget[0] -= 1
        if budget[0] < 0:
            return
        # the best this branch can reach: every later label that has a place shown, at its preferred side
        reach = (count + sum(possible[i:]), tuple(c is not None for c in chosen[:i]) + tuple(possible[i:]), -rank)
        if reach <= best_score:
            return
        if i == n:
            best_score, best = reach, list(chosen)
            return
        for k, opt in enumerate(options[i]):
            if not any(p is not None and table[(j, i)][p, k] for j, p in enumerate(picked[:i])):
                chosen[i], picked[i] = opt, k
                search(i + 1, count + 1, rank + opt[0])
        chosen[i], picked[i] = None, None
        search(i + 1, count, rank)

    search(0, 0, 0)
    placed = [c for c in best if c is not None]
    for opts in options[n:]:  # the rest (minor labels) greedily around them
        pick = next((o for o in opts if not any(clash(o[2], c[2]) for c in placed)), None)
        best.append(pick)
        if pick is not None:
            placed.append(pick)
    for lab, c in zip(labels, best, strict=True):
        out[lab.key] = None if c is None else (c[1], c[2], c[3])
    return out


__all__ = ["ANCHOR_OFFSET", "CHAR_PX", "FALLBACK_ANCHORS", "GAP_PX", "PAD_PX", "TEXT_PX", "Label", "box_at",
           "boxes_overlap", "label_box_px", "place_labels", "place_labels_in_views", "project_px", "View"]
