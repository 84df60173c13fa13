"""Framing the 3D view: a camera pose that makes the image footprint fill the view.

Pure numpy (no viser): the pose is computed for the camera model of viser's client -- a three.js
perspective camera with a *vertical* field of view ``fov_y``, ``aspect = width / height`` of the
canvas, ``+z`` up (``server.scene.set_up_direction("+z")``) -- and :func:`view_ndc` projects points
through that same model, so a test checks the framing in closed form.

The footprint is what a user looks at (the SCPs coloured by their residual lie on it): the pose puts
its outline at :data:`FOOTPRINT_FILL` of the view along the binding axis (the width on the tall canvas
between the explorer's two docked panels) and wholly inside the view, seen obliquely from the side of
the flight.  Within that, the look-at point is raised towards the displayed satellite track as far as
the footprint stays inside the view, so as much of the track and of the scanline planes shows as the
canvas allows.  Display units: ``docs/explorer.md#frame`` (km).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

VIEW_FOV_Y = np.deg2rad(75.0)
"""viser's default vertical field of view of a client's camera, radians (what the browser reports)."""
DEFAULT_ASPECT = 512.0 / 900.0
"""Canvas width / height assumed before a browser reports its own: the 3D canvas between the two docked
panels of a 1400 x 900 window (measured in Chromium: 512 x 900 px)."""
DEFAULT_CANVAS_PX = (512, 900)
"""That canvas in pixels (the labels, a fixed number of pixels tall, are laid out for it)."""
FOOTPRINT_FILL = 0.7
"""Share of the view the footprint spans along the binding axis (width or height)."""
VIEW_MARGIN = 0.85
"""Every footprint point lies inside this share of the view's half-extent (NDC), both axes (the rest is room
for the labels anchored at the footprint's edges)."""
ELEVATION_DEG = 35.0
"""Elevation of the viewing direction above the horizon (oblique: the footprint and its relief show)."""
BEHIND_DEG = 20.0
"""Azimuth of the viewing direction from the across-track side, towards the start of the flight."""


@dataclass(frozen=True)
class CameraPose:
    """A perspective camera, display km.

    Attributes
    ----------
    position, look_at : ndarray, shape (3,)
    fov_y : float
        Vertical field of view, radians.
    aspect : float
        Canvas width / height the pose was made for.
    near, far : float
        Clipping distances, km.
    """

    position: np.ndarray
    look_at: np.ndarray
    fov_y: float
    aspect: float
    near: float
    far: float


def camera_axes(position: np.ndarray, look_at: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """Rows (right, true up, forward) (3, 3) of a camera at ``position`` looking at ``look_at`` with ``up``
    (default ``+z``) kept upright, as three.js's ``lookAt`` does."""
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64)
    f = np.asarray(look_at, dtype=np.float64) - np.asarray(position, dtype=np.float64)
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-12:  # looking straight along up: any right vector
        r = np.cross(f, [1.0, 0.0, 0.0])
    r /= np.linalg.norm(r)
    return np.stack([r, np.cross(r, f), f])


def view_ndc(points: np.ndarray, position: np.ndarray, look_at: np.ndarray, *, fov_y: float = VIEW_FOV_Y,
             aspect: float = DEFAULT_ASPECT) -> tuple[np.ndarray, np.ndarray]:
    """Points projected through a perspective camera.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Display km.
    position, look_at : ndarray, shape (3,)
    fov_y : float
        Vertical field of view, radians.
    aspect : float
        Width / height of the canvas.

    Returns
    -------
    ndc : ndarray, shape (N, 2)
        Normalised device coordinates (x right, y up): the view is ``[-1, 1]^2``.
    depth : ndarray, shape (N,)
        Distance in front of the camera along its axis, km (<= 0: behind).
    """
    axes = camera_axes(position, look_at)
    v = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(position, dtype=np.float64)) @ axes.T
    depth = v[:, 2]
    t = np.tan(0.5 * fov_y)
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = np.stack([v[:, 0] / (depth * t * aspect), v[:, 1] / (depth * t)], axis=1)
    return ndc, depth


def view_direction(flight: np.ndarray, *, elevation_deg: float = ELEVATION_DEG,
                   behind_deg: float = BEHIND_DEG) -> np.ndarray:
    """Unit vector (3,) from the look-at point towards the camera: on the right of the flight, turned
    ``behind_deg`` towards its start, ``elevation_deg`` above the horizon."""
    f = np.array([flight[0], flight[1], 0.0], dtype=np.float64)
    n = np.linalg.norm(f)
    f = f / n if n > 1e-12 else np.array([0.0, 1.0, 0.0])
    side = np.cross(f, [0.0, 0.0, 1.0])
    az, el = np.deg2rad(behind_deg), np.deg2rad(elevation_deg)
    horiz = np.cos(az) * side - np.sin(az) * f
    return np.cos(el) * horiz + np.array([0.0, 0.0, np.sin(el)])


def _distance_for_fill(ground: np.ndarray, look: np.ndarray, w: np.ndarray, fov_y: float, aspect: float,
                       fill: float, scale: float) -> float:
    """Camera distance at which the ground points span ``fill`` of the view along the binding axis."""

    # the camera's axes do not depend on its distance along w: project once, move along the axis per distance
    axes = camera_axes(look + w, look)
    rel = (ground - look) @ axes.T
    step = np.asarray(w, dtype=np.float64) @ axes.T
    t = np.tan(0.5 * fov_y)

    def span(d: float) -> float:
        v = rel - d * step
        depth = v[:, 2]
        if np.any(depth <= 1e-9 * scale):
            return np.inf
        ndc_x, ndc_y = v[:, 0] / (depth * t * aspect), v[:, 1] / (depth * t)
        return float(max(np.ptp(ndc_x), np.ptp(ndc_y)) / 2.0)

    lo, hi = 1e-3 * scale, 1e3 * scale
    for _ in range(36):  # the span shrinks as the camera backs away: bisect on log distance
        mid = float(np.sqrt(lo * hi))
        if span(mid) > fill:
            lo = mid
        else:
            hi = mid
    return hi


def frame_footprint(ground: np.ndarray, track: np.ndarray, *, fov_y: float = VIEW_FOV_Y,
                    aspect: float = DEFAULT_ASPECT, fill: float = FOOTPRINT_FILL,
                    margin: float = VIEW_MARGIN, include: np.ndarray | None = None) -> CameraPose:
    """A camera pose in which the footprint fills ``fill`` of the view.

    Parameters
    ----------
    ground : ndarray, shape (M, 3)
        Points of the footprint's outline as displayed (heights exaggerated), display km.
    track : ndarray, shape (K, 3)
        Displayed perspective centres in flight order (K >= 2), display km.
    fov_y, aspect : float
        The browser camera's vertical field of view (radians) and canvas width / height.
    fill : float
        Share of the view spanned by the footprint along the binding axis (in (0, margin]).
    margin : float
        The footprint stays inside this share of the view's half-extent on both axes.
    include : ndarray, shape (L, 3), optional
        Points that must be inside the view too (within ``margin``, in front of the camera): for example what
        is drawn around the track (a refinement's trajectories, :func:`explorer.scene3d.refine.trajectory_envelope`).
        The footprint still spans at least half of the view; where that cannot hold them as well, ValueError.

    Returns
    -------
    CameraPose
        From :func:`view_direction`, looking at the footprint centre raised towards the track's middle as
        far as the footprint stays inside the margins (at most half-way; lowered if perspective needs it).
        Where ``fill`` cannot fit inside the margins (a very long footprint seen obliquely), the largest of
        ``fill``, ``fill - 0.05``, ... down to 0.5 that fits.
    """
    if not 0.0 < fill <= margin <= 1.0:
        raise ValueError(f"need 0 < fill <= margin <= 1, got fill={fill}, margin={margin}")
    if not aspect > 0 or not 0.0 < fov_y < np.pi:
        raise ValueError(f"aspect must be > 0 and fov_y in (0, pi), got {aspect}, {fov_y}")
    ground = np.asarray(ground, dtype=np.float64).reshape(-1, 3)
    track = np.asarray(track, dtype=np.float64).reshape(-1, 3)
    centre = 0.5 * (ground.min(axis=0) + ground.max(axis=0))
    scale = float(np.max(np.ptp(ground, axis=0))) or 1.0
    w = view_direction(track[-1] - track[0])
    mid = track[len(track) // 2]
    extra = None if include is None else np.asarray(include, dtype=np.float64).reshape(-1, 3)
    def fits(lam: float, share: float) -> tuple[np.ndarray, float] | None:
        look = centre + lam * (mid - centre)
        d = _distance_for_fill(ground, look, w, fov_y, aspect, share, scale)
        ndc, depth = view_ndc(ground, look + d * w, look, fov_y=fov_y, aspect=aspect)
        if not (np.all(depth > 0) and np.all(np.abs(ndc) <= margin)):
            return None
        if extra is not None:
            ndc, depth = view_ndc(extra, look + d * w, look, fov_y=fov_y, aspect=aspect)
            if not (np.all(depth > 0) and np.all(np.abs(ndc) <= margin)):
                return None
        return look, d

    best = None
    for share in np.arange(fill, 0.5 - 1e-9, -0.05):  # the fill asked for, less only if it cannot fit
        # the look-at point as high towards the track as the footprint allows (lowered below the footprint's
        # centre when perspective pushes its near edge out of the view): coarse steps, then bisection
        above = None
        for lam in np.linspace(0.5, -0.5, 21):
            best = fits(lam, float(share))
            if best is not None:
                break
            above = lam
        if best is None:
            continue
        if above is not None:
            lo, hi = lam, above
            for _ in range(5):
                m = 0.5 * (lo + hi)
                got = fits(m, float(share))
                if got is not None:
                    best, lo = got, m
                else:
                    hi = m
        break
    if best is None:
        if extra is not None:
            raise ValueError("the footprint and the points to include cannot be framed with the footprint at half "
                             "of the view")
        raise ValueError("the footprint cannot be framed at half of the view (a degenerate footprint?)")
    look, d = best
    position = look + d * w
    drawn = np.concatenate([ground, track] + ([] if extra is None else [extra]))
    reach = float(np.max(np.linalg.norm(drawn - position, axis=1)))
    near = float(np.clip(1e-3 * d, 1e-4, 0.05))
    return CameraPose(position, look, float(fov_y), float(aspect), near, max(10.0 * reach, 5000.0))


def footprint_share(ground: np.ndarray, pose: CameraPose, aspect: float | None = None) -> tuple[float, float]:
    """(width share, height share) of the view spanned by the ground points seen from ``pose``
    (clipped to the view: a point outside counts only up to the edge)."""
    ndc, _ = view_ndc(ground, pose.position, pose.look_at, fov_y=pose.fov_y,
                      aspect=pose.aspect if aspect is None else aspect)
    ndc = np.clip(ndc, -1.0, 1.0)
    return float(np.ptp(ndc[:, 0]) / 2.0), float(np.ptp(ndc[:, 1]) / 2.0)


__all__ = ["DEFAULT_ASPECT", "DEFAULT_CANVAS_PX", "FOOTPRINT_FILL", "VIEW_FOV_Y", "VIEW_MARGIN", "CameraPose",
           "camera_axes", "footprint_share", "frame_footprint", "view_direction", "view_ndc"]
