"""Scenes and check points shared by the method tests (cached: building them is the slow part)."""

from __future__ import annotations

from functools import cache

import numpy as np

from explorer.geometry.interior import InteriorOrientation
from explorer.points import PointSet, simulate_points
from explorer.presets import build_scene
from explorer.scene import Scene

N_SCPS = 2000


@cache
def scene_for(preset: str, relief: float = 0.0, jitter: float = 1.0) -> Scene:
    """A preset scene, optionally with seeded relief (seed 3) and scaled jitter."""
    return build_scene(preset, relief_m=relief, relief_seed=3, jitter_amplitude_scale=jitter)


@cache
def scps_for(preset: str, relief: float = 0.0, jitter: float = 1.0) -> PointSet:
    """Cell-centred check points with exact rows on :func:`scene_for`."""
    return simulate_points(scene_for(preset, relief, jitter), N_SCPS, kind="scp")


def curved_scene(preset: str = "WSU") -> Scene:
    """Offset, curved detector line and radial distortion on a preset's orbit."""
    base = scene_for(preset)
    pitch = base.interior.detector_pitch_m
    interior = InteriorOrientation(
        base.interior.focal_length_m, pitch, base.n_columns, principal_column=base.n_columns / 2 - 17.7,
        along_track_offset_m=37.2 * pitch, line_curvature=(2e-4, 3e-3), radial_distortion=(2e-3,),
    )
    return Scene("curved", interior, base.exterior, base.timing, base.n_rows, base.terrain, base.frame)


def interpolation_bound(scene: Scene, ground: np.ndarray, row: np.ndarray) -> np.ndarray:
    """Independent bound (rows) of linear interpolation of the residual between the integer lines
    around ``row``: |x''| / (8 |x'|), x'' from second differences on the lines around them."""
    l1 = np.floor(row)
    f = np.array([scene.along_track_residual(ground, scene.scanline_time(l1 + k)) for k in (-1, 0, 1, 2)])
    d2 = np.maximum(np.abs(f[0] - 2 * f[1] + f[2]), np.abs(f[1] - 2 * f[2] + f[3]))
    return d2 / (8 * np.abs(f[2] - f[1]))
