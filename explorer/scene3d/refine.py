"""viser builder of a refinement's trajectories: the original and the adjusted perspective centres and attitudes.

Model results in (:class:`explorer.refine.trajectory.TrajectoryComparison`), scene nodes out.  An adjustment
moves a perspective centre by metres and turns the camera by microradians: drawn at true scale both are
invisible beside a footprint of kilometres, so the adjusted trajectory is drawn with its displacement from the
original multiplied by ``position_factor`` and its attitude change (the rotation angle, about the same axis)
by ``attitude_factor``; both factors are stated in the scene's label and returned for the GUI to state.
Sensor-side points go through :meth:`DisplayFrame.sensor` like the satellite track of
:func:`explorer.scene3d.builders.add_orbit` (``docs/explorer.md#frame``), so the original trajectory lies on it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from explorer.scene3d.builders import KM, DisplayFrame, Handles

if TYPE_CHECKING:  # pragma: no cover
    import viser

    from explorer.refine.trajectory import TrajectoryComparison

__all__ = ["ADJUSTED_RGB", "FRAMED_ASPECTS", "ORIGINAL_RGB", "REFINE_DISTANCE_FACTORS", "add_refined_trajectories",
           "auto_factors", "framed_distance_factor", "nice_factor", "trajectory_envelope", "triad_segments"]

ORIGINAL_RGB = (110, 110, 110)
ADJUSTED_RGB = (214, 39, 40)
POSITION_SHARE = 0.1
"""Automatic position factor: the largest displacement is drawn as about this share of the footprint diagonal."""
ATTITUDE_TARGET_RAD = 0.2
"""Automatic attitude factor: the largest attitude change is drawn as about this angle (about 11 degrees)."""
TRIAD_SHARE = 0.12
"""Length of a drawn camera axis, in footprint diagonals (as the sensor frames of the orbit)."""
REFINE_DISTANCE_FACTORS = (2.5, 2.0, 1.5, 1.2, 1.0, 0.8, 0.6, 0.5, 0.4, 0.3, 0.25, 0.2)
"""Compressed sensor distances (scene centre -> middle of the track, in footprint diagonals) tried, largest first,
when a refinement is shown (:func:`framed_distance_factor`); the default view's is
:data:`explorer.scene3d.builders.COMPRESSED_DISTANCE_FACTOR`."""
FRAMED_ASPECTS = (512.0 / 900.0,)
"""Canvas shapes (width / height) in whose framed view the trajectories must fit: the default canvas between the
explorer's docked panels (:data:`explorer.scene3d.camera.DEFAULT_ASPECT`).  A browser whose canvas has another
shape gets its own framing with the trajectories inside where the footprint can keep half of its view (a wide
canvas may need a smaller distance than this one: there the footprint comes first)."""
_ENVELOPE_DIRECTIONS = np.concatenate([np.vstack([np.eye(3), -np.eye(3)]),
                                       np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
                                       / np.sqrt(3.0)])


def nice_factor(want: float) -> float:
    """The largest of 1, 2, 5, 10, 20, 50, ... not above ``want`` (to 1e-9 relative; 1 for ``want`` <= 1 or not
    finite)."""
    if not (np.isfinite(want) and want > 1.0):
        return 1.0
    want *= 1.0 + 1e-9  # a change computed a rounding above a round figure keeps the round factor
    decade = 10.0 ** np.floor(np.log10(want))
    return float(max(m * decade for m in (1.0, 2.0, 5.0) if m * decade <= want))


def auto_factors(comparison: TrajectoryComparison, frame: DisplayFrame) -> tuple[float, float]:
    """(position_factor, attitude_factor) that make the adjustment visible: the largest displacement drawn as
    :data:`POSITION_SHARE` of the footprint diagonal, the largest attitude change as :data:`ATTITUDE_TARGET_RAD`."""
    moved = float(np.max(np.linalg.norm(comparison.displacement_m, axis=1)))
    turned = float(np.max(comparison.attitude_change_rad))
    diagonal_m = frame.diagonal_km * KM
    position = nice_factor(POSITION_SHARE * diagonal_m / moved) if moved > 0 else 1.0
    attitude = nice_factor(ATTITUDE_TARGET_RAD / turned) if turned > 0 else 1.0
    return position, attitude


def trajectory_envelope(track_km: np.ndarray, diagonal_km: float) -> np.ndarray:
    """Points (14 K, 3) around a displayed track (K, 3) km that hold what :func:`add_refined_trajectories` draws
    with its automatic factors, whatever the adjustment: the adjusted centres lie within :data:`POSITION_SHARE`
    footprint diagonals of the original ones and the camera axes are :data:`TRIAD_SHARE` long, so every drawn
    point is within their sum of the track (14 directions per sample: the axes and the cube's diagonals).  What
    the framing (:func:`explorer.scene3d.camera.frame_footprint`'s ``include``) keeps in the view, so the
    default view holds the trajectories and a re-adjustment needs no new camera."""
    reach = POSITION_SHARE * float(diagonal_km)
    t = np.asarray(track_km, dtype=np.float64).reshape(-1, 3)
    return (t[:, None, :] + reach * _ENVELOPE_DIRECTIONS[None, :, :]).reshape(-1, 3)


def framed_distance_factor(scene: Any, *, height_exaggeration: float = 1.0,
                           aspects: tuple[float, ...] = FRAMED_ASPECTS,
                           factors: tuple[float, ...] = REFINE_DISTANCE_FACTORS) -> float:
    """The compressed sensor distance (footprint diagonals from the scene centre to the middle of the track) at
    which the framed view holds the refinement's trajectories: the largest of ``factors`` at which
    :func:`explorer.scene3d.camera.frame_footprint` frames the footprint (at least half of the view) with the
    :func:`trajectory_envelope` of the displayed track inside the view, on every canvas shape of ``aspects``;
    the smallest of ``factors`` if none does.

    At the default distance (2.5 diagonals) the track sits above the framed view of a footprint that fills
    70 % of it: the user had to zoom out to find the trajectories.  The smaller distance is a translation of
    every sensor-side point (track, sensor frames, trajectories, scanline planes) as the default one is
    (``docs/explorer.md#frame``), stated in the view.
    """
    from explorer.scene3d import builders as B  # noqa: N812
    from explorer.scene3d.camera import frame_footprint

    _, pos = B.track_positions(scene, 9)
    frame = DisplayFrame.for_scene(scene, height_exaggeration=height_exaggeration)
    ground = frame.ground(B.footprint_outline(scene, per_edge=16).reshape(-1, 3))  # independent of the distance

    def frames(f: float) -> bool:
        shown = DisplayFrame.for_scene(scene, height_exaggeration=height_exaggeration, factor=f)
        track = shown.sensor(pos)
        envelope = trajectory_envelope(track, shown.diagonal_km)
        try:
            for aspect in aspects:  # (at the least fill the framing accepts: the one with most room)
                frame_footprint(ground, track, aspect=aspect, include=envelope, fill=0.5)
        except ValueError:
            return False
        return True

    # the track comes into the view as it comes down: bisect the (decreasing) ladder for the first that frames
    lo, hi = 0, len(factors) - 1
    if frames(factors[lo]):
        return float(factors[lo])
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if frames(factors[mid]):
            hi = mid
        else:
            lo = mid
    return float(factors[hi])


def triad_segments(centres_km: np.ndarray, attitudes: np.ndarray, length_km: float) -> np.ndarray:
    """Line segments (3 n, 2, 3) of the camera axes x, y, z (columns of the camera -> ENU rotations
    (n, 3, 3)) from displayed centres (n, 3) km, ``length_km`` long; ordered x, y, z per centre."""
    c = np.asarray(centres_km, dtype=np.float64).reshape(-1, 3)
    axes = np.transpose(np.asarray(attitudes, dtype=np.float64).reshape(-1, 3, 3), (0, 2, 1))  # rows = axes
    tips = c[:, None, :] + length_km * axes
    return np.stack([np.repeat(c[:, None, :], 3, axis=1), tips], axis=2).reshape(-1, 2, 3)


def add_refined_trajectories(
    api: viser.SceneApi,
    comparison: TrajectoryComparison,
    frame: DisplayFrame,
    *,
    position_factor: float | None = None,
    attitude_factor: float | None = None,
    n_frames: int = 5,
) -> tuple[Handles, dict[str, Any]]:
    """Draw the original (grey) and adjusted (red) trajectories with camera triads at ``n_frames`` line times.

    Nodes: ``/refine/original/track``, ``/refine/adjusted/track`` (line segments through the sampled centres),
    ``/refine/original/attitude``, ``/refine/adjusted/attitude`` (the camera's x, y, z axes, line segments),
    ``/refine/label``.

    Returns
    -------
    handles : dict
    info : dict
        ``position_factor``, ``attitude_factor`` (as drawn), ``text`` (what was drawn, with the true ranges and,
        at a compressed distance, the drawn and true distance of the middle perspective centre from the scene
        centre, for the GUI), ``label`` (the scene's short label, at the middle of the adjusted track),
        ``label_alternatives`` (other points of the adjusted track, display km, where the label may stand),
        ``display_distance_km`` / ``true_distance_km`` and the comparison's
        :meth:`~explorer.refine.trajectory.TrajectoryComparison.summary`.
    """
    auto_p, auto_a = auto_factors(comparison, frame)
    kp = auto_p if position_factor is None else float(position_factor)
    ka = auto_a if attitude_factor is None else float(attitude_factor)
    centres, attitudes = comparison.exaggerated(kp)
    if ka != kp:
        attitudes = comparison.exaggerated(ka)[1]
    pick = np.unique(np.linspace(0, len(comparison.rows) - 1, max(n_frames, 2)).round().astype(int))
    length = TRIAD_SHARE * frame.diagonal_km
    out: Handles = {}
    for label, pos, att, rgb in (("original", comparison.original_centre_m, comparison.original_attitude, ORIGINAL_RGB),
                                 ("adjusted", centres, attitudes, ADJUSTED_RGB)):
        shown = frame.sensor(pos)
        track = np.stack([shown[:-1], shown[1:]], axis=1)
        out[f"/refine/{label}/track"] = api.add_line_segments(
            f"/refine/{label}/track", track, rgb, thickness=4.0 if label == "adjusted" else 3.0,
            thickness_units="screen")
        out[f"/refine/{label}/attitude"] = api.add_line_segments(
            f"/refine/{label}/attitude", triad_segments(shown[pick], att[pick], length), rgb, thickness=2.5,
            thickness_units="screen")
    summary = comparison.summary()
    d, a = summary["displacement_m"], summary["attitude_change_urad"]
    text = (f"adjusted trajectory (red) vs original (grey): centres moved {d[0]:.3g}..{d[1]:.3g} m, drawn x{kp:g}; "
            f"attitude turned {a[0]:.3g}..{a[1]:.3g} urad, drawn x{ka:g}")
    label = f"adjusted trajectory (red): position x{kp:g}, attitude x{ka:g}"
    shown_adjusted = frame.sensor(centres)
    middle = shown_adjusted[len(centres) // 2]
    # other places along the red track the label may stand at (the app's label layout picks one clear of the rest)
    others = shown_adjusted[np.unique(np.linspace(0, len(centres) - 1, 5).round().astype(int))]
    out["/refine/label"] = api.add_label("/refine/label", label, position=middle, anchor="bottom-center")
    mid_centre = comparison.original_centre_m[len(centres) // 2]
    distance = float(np.linalg.norm(frame.sensor(mid_centre[None])[0]))  # display km from the scene centre
    true_distance = float(np.linalg.norm(mid_centre - frame.origin_m)) / KM
    if frame.compressed:
        text += (f"; the sensor side drawn {distance:.3g} km from the scene centre (true {true_distance:.4g} km: "
                 "compressed distance)")
    return out, {"position_factor": kp, "attitude_factor": ka, "text": text, "label": label,
                 "label_alternatives": [p for p in others if not np.array_equal(p, middle)],
                 "display_distance_km": distance, "true_distance_km": true_distance, **summary}
