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

__all__ = ["ADJUSTED_RGB", "ORIGINAL_RGB", "add_refined_trajectories", "auto_factors", "nice_factor",
           "triad_segments"]

ORIGINAL_RGB = (110, 110, 110)
ADJUSTED_RGB = (214, 39, 40)
POSITION_SHARE = 0.1
"""Automatic position factor: the largest displacement is drawn as about this share of the footprint diagonal."""
ATTITUDE_TARGET_RAD = 0.2
"""Automatic attitude factor: the largest attitude change is drawn as about this angle (about 11 degrees)."""
TRIAD_SHARE = 0.12
"""Length of a drawn camera axis, in footprint diagonals (as the sensor frames of the orbit)."""


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
        ``position_factor``, ``attitude_factor`` (as drawn), ``text`` (what was drawn, with the true ranges, for
        the GUI), ``label`` (the scene's short label, at the middle of the adjusted track), and the comparison's
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
    middle = frame.sensor(centres[len(centres) // 2: len(centres) // 2 + 1])[0]
    out["/refine/label"] = api.add_label("/refine/label", label, position=middle, anchor="bottom-center")
    return out, {"position_factor": kp, "attitude_factor": ka, "text": text, "label": label, **summary}
