"""Scenes shared by the geometry and method tests (one definition of each special camera)."""

from __future__ import annotations

from explorer.geometry.exterior import Jitter
from explorer.geometry.interior import InteriorOrientation
from explorer.presets import build_scene
from explorer.scene import Scene


def curved_scene(preset: str = "WSU", jitter: bool = False, principal_column: float | None = None) -> Scene:
    """A preset's orbit with a displaced (37.2 px), curved detector line, an off-centre principal point
    (default 17.7 px left of the centre) and radial distortion; ``jitter`` adds two attitude sinusoids
    (23 and 57 Hz)."""
    base = build_scene(preset)
    centre = base.n_columns / 2 - 17.7 if principal_column is None else principal_column
    pitch = base.interior.detector_pitch_m
    interior = InteriorOrientation(
        base.interior.focal_length_m, pitch, base.n_columns, principal_column=centre,
        along_track_offset_m=37.2 * pitch, line_curvature=(2e-4, 3e-3), radial_distortion=(2e-3,),
    )
    exterior = base.exterior
    if jitter:
        exterior.jitter = [Jitter("kappa", 4e-6, 23.0, 0.4), Jitter("phi", 2e-6, 57.0, 1.3)]
    return Scene("curved", interior, exterior, base.timing, base.n_rows, base.terrain, base.frame)
