"""The collinearity equations of a pushbroom scanline.

For ground point P, perspective centre S(t) and sensor->object rotation R(t),
``v = R(t).T @ (P - S(t))`` and the ideal focal-plane coordinates are

    x = -f v_x / v_z   (along track),     y = -f v_y / v_z   (across track).

The best scanline is the time t at which the measured x equals the detector line's
along-track position (``docs/conventions.md#best-scanline``).
"""

from __future__ import annotations

import numpy as np


def sensor_vectors(ground: np.ndarray, centre: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``v = R.T (P - S)`` for each point.

    Parameters
    ----------
    ground, centre : ndarray, shape (N, 3)
        Ground points and perspective centres, metres (local ENU).
    rotation : ndarray, shape (N, 3, 3)
        Sensor -> object rotations.

    Returns
    -------
    ndarray, shape (N, 3)
        The ground point in the sensor frame (metres); ``v_z < 0`` in front of the camera.
    """
    d = ground - centre
    return np.einsum("nji,nj->ni", rotation, d)


def ideal_focal_plane(
    ground: np.ndarray, centre: np.ndarray, rotation: np.ndarray, focal_length_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Ideal (pinhole) focal-plane coordinates (x, y), each (N,), metres."""
    v = sensor_vectors(ground, centre, rotation)
    scale = -focal_length_m / v[:, 2]
    return v[:, 0] * scale, v[:, 1] * scale
