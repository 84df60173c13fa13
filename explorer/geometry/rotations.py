"""Rotation matrices from omega, phi, kappa (sequential, photogrammetric order).

Convention (``docs/conventions.md#rotations``): the matrix ``R`` rotates sensor-frame
vectors into the object (local ENU) frame,

    R = R_x(omega) @ R_y(phi) @ R_z(kappa)

with right-handed active elementary rotations.  The collinearity equations use
``M = R.T`` (object -> sensor).  With omega = phi = 0 the sensor x axis (along track)
points at azimuth 90 deg - kappa (kappa is measured counter-clockwise from east).
"""

from __future__ import annotations

import numpy as np


def rotation_from_opk(omega: np.ndarray, phi: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    """Sensor -> object rotation matrices.

    Parameters
    ----------
    omega, phi, kappa : array_like, shape (N,)
        Angles in radians (any broadcastable shape ``S``).

    Returns
    -------
    ndarray, shape S + (3, 3)
        ``R = R_x(omega) R_y(phi) R_z(kappa)``.
    """
    omega, phi, kappa = np.broadcast_arrays(
        np.asarray(omega, dtype=np.float64),
        np.asarray(phi, dtype=np.float64),
        np.asarray(kappa, dtype=np.float64),
    )
    so, co = np.sin(omega), np.cos(omega)
    sp, cp = np.sin(phi), np.cos(phi)
    sk, ck = np.sin(kappa), np.cos(kappa)
    r = np.empty(omega.shape + (3, 3), dtype=np.float64)
    r[..., 0, 0] = cp * ck
    r[..., 0, 1] = -cp * sk
    r[..., 0, 2] = sp
    r[..., 1, 0] = co * sk + so * sp * ck
    r[..., 1, 1] = co * ck - so * sp * sk
    r[..., 1, 2] = -so * cp
    r[..., 2, 0] = so * sk - co * sp * ck
    r[..., 2, 1] = so * ck + co * sp * sk
    r[..., 2, 2] = co * cp
    return r


def opk_from_rotation(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`rotation_from_opk` for |phi| < 90 deg.

    Parameters
    ----------
    r : ndarray, shape S + (3, 3)

    Returns
    -------
    omega, phi, kappa : ndarray, shape S
        Radians.
    """
    r = np.asarray(r, dtype=np.float64)
    omega = np.arctan2(-r[..., 1, 2], r[..., 2, 2])
    phi = np.arcsin(np.clip(r[..., 0, 2], -1.0, 1.0))
    kappa = np.arctan2(-r[..., 0, 1], r[..., 0, 0])
    return omega, phi, kappa


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` (radians) about unit ``axis`` (3,), Rodrigues' formula; shape (3, 3)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
