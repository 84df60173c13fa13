"""3D scene elements of a stereo pair (``pushbroom explore --pair``): both trajectories and footprints, a
selected pixel's two lines of sight meeting on the ground.  Numbers from :mod:`explorer.stereo.pairview` (left
sensor's ENU metres) in, viser nodes out."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from explorer.scene3d.builders import DisplayFrame

if TYPE_CHECKING:  # typing only
    import viser

    from explorer.stereo.pairview import PairSelection

LEFT_RGB = (31, 119, 180)
RIGHT_RGB = (214, 39, 40)
GROUND_RGB = (255, 200, 0)

Handles = dict[str, Any]


def pair_display_frame(outlines: tuple[np.ndarray, np.ndarray], tracks: tuple[np.ndarray | None, np.ndarray | None],
                       factor: float = 1.5) -> DisplayFrame:
    """Display frame of a pair: origin at the footprints' centre, the sensors pulled in to ``factor`` footprint
    diagonals (the single-image explorer's compressed distance)."""
    ground = np.concatenate(outlines)
    centre = ground.mean(axis=0)
    diag = float(np.linalg.norm(ground.max(axis=0) - ground.min(axis=0)))
    shift = np.zeros(3)
    track_pts = [t for t in tracks if t is not None]
    if track_pts:
        mid = np.concatenate(track_pts).mean(axis=0)
        los = mid - centre
        dist = float(np.linalg.norm(los))
        if dist > factor * diag:
            shift = (1.0 - factor * diag / dist) * los
    return DisplayFrame(centre, shift, 1.0, diag / 1000.0)


def add_pair(api: viser.SceneApi, frame: DisplayFrame, outlines: tuple[np.ndarray, np.ndarray],
             tracks: tuple[np.ndarray | None, np.ndarray | None]) -> Handles:
    """Footprint outlines (``/pair/left/footprint``, ``/pair/right/footprint``) and trajectories
    (``/pair/<side>/track``), left in blue and right in red."""
    out: Handles = {}
    for side, outline, track, rgb in (("left", outlines[0], tracks[0], LEFT_RGB),
                                      ("right", outlines[1], tracks[1], RIGHT_RGB)):
        g = frame.ground(outline)
        out[f"/pair/{side}/footprint"] = api.add_line_segments(
            f"/pair/{side}/footprint", np.stack([g[:-1], g[1:]], axis=1), rgb, thickness=2.0,
            thickness_units="screen")
        if track is not None:
            t = frame.sensor(track)
            out[f"/pair/{side}/track"] = api.add_spline_catmull_rom(
                f"/pair/{side}/track", t, thickness=3.0, thickness_units="screen", color=rgb)
            out[f"/pair/{side}/label"] = api.add_label(f"/pair/{side}/label", f"{side} image, first row",
                                                       position=t[0], anchor="top-right")
    return out


def add_pair_selection(api: viser.SceneApi, frame: DisplayFrame, sel: PairSelection) -> Handles:
    """The selected pixel's ground point (``/pair/selected/point``) and its two lines of sight from the
    perspective centres (``/pair/selected/left_ray``, ``/pair/selected/right_ray``)."""
    out: Handles = {}
    p = frame.ground(sel.ground[None, :])[0]
    out["/pair/selected/point"] = api.add_icosphere("/pair/selected/point", radius=0.015 * frame.diagonal_km,
                                                    color=GROUND_RGB, position=p, cast_shadow=False)
    for side, centre, rgb in (("left", sel.left_centre, LEFT_RGB), ("right", sel.right_centre, RIGHT_RGB)):
        if centre is None:
            continue
        s = frame.sensor(centre[None, :])[0]
        out[f"/pair/selected/{side}_ray"] = api.add_line_segments(
            f"/pair/selected/{side}_ray", np.stack([s, p])[None], rgb, thickness=2.5, thickness_units="screen")
    out["/pair/selected/label"] = api.add_label(
        "/pair/selected/label", f"h {sel.height:.1f} m, rays {float(sel.check.ray_distance_m[0]) * 1000:.2g} mm apart",
        position=p, anchor="bottom-left")
    return out


__all__ = ["add_pair", "add_pair_selection", "pair_display_frame"]
