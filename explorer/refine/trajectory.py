"""The original and the adjusted trajectory and attitude of a refined line-scan sensor, along its line time.

What the 3D scene (:mod:`explorer.scene3d.refine`) and the trajectory panel
(:func:`explorer.panels.refine.trajectory_figure`) draw: perspective centres and camera -> local ENU rotations
of the sensor before and after the adjustment, sampled at the same rows (the same line times), read through the
line-geometry capability of :class:`explorer.sensor.LineGeometrySensor` (``line_time``, ``perspective_centre``,
``attitude``), so any refined sensor that has scanlines -- an MPC scene, a rigorous or CSM model -- gives its
trajectory the same way.  An RPC has no scanlines and no trajectory.

Frames and rotations: ``docs/conventions.md#frames`` and ``#rotations`` (the camera looks along its ``-z``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # typing only
    from explorer.refine.adjust import Refinement

__all__ = ["TrajectoryComparison", "refinement_trajectory", "rotation_angle", "trajectory_comparison"]


def rotation_angle(rot: np.ndarray) -> np.ndarray:
    """Angle (N,) radians of rotation matrices (N, 3, 3), accurate for small angles too.

    ``atan2(|axial vector|, (trace - 1) / 2)`` with the axial vector ``(R - R^T) / 2``: no ``arccos`` near 1.
    """
    m = np.asarray(rot, dtype=np.float64).reshape(-1, 3, 3)
    axial = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
    cos = 0.5 * (np.trace(m, axis1=1, axis2=2) - 1.0)
    return np.arctan2(np.linalg.norm(axial, axis=1), cos)


@dataclass(frozen=True)
class TrajectoryComparison:
    """Perspective centres and attitudes of a sensor before and after its adjustment, at the same line times.

    Attributes
    ----------
    rows : ndarray, shape (n,)
        Image rows sampled, from the first to the last scanline edge (``-0.5`` .. ``rows - 0.5``).
    time_s : ndarray, shape (n,)
        Their line times, seconds on the original sensor's clock.
    original_centre_m, adjusted_centre_m : ndarray, shape (n, 3)
        Perspective centres, local ENU metres of the sensor's frame.
    original_attitude, adjusted_attitude : ndarray, shape (n, 3, 3)
        Camera -> local ENU rotations.
    """

    rows: np.ndarray
    time_s: np.ndarray
    original_centre_m: np.ndarray
    adjusted_centre_m: np.ndarray
    original_attitude: np.ndarray
    adjusted_attitude: np.ndarray

    @property
    def displacement_m(self) -> np.ndarray:
        """Adjusted minus original perspective centre (n, 3), metres."""
        return self.adjusted_centre_m - self.original_centre_m

    @property
    def attitude_change(self) -> np.ndarray:
        """Rotations (n, 3, 3) taking the original camera axes to the adjusted ones, in local ENU
        (``adjusted = change @ original``)."""
        return self.adjusted_attitude @ np.transpose(self.original_attitude, (0, 2, 1))

    @property
    def attitude_change_rad(self) -> np.ndarray:
        """Angle (n,) of :attr:`attitude_change`, radians."""
        return rotation_angle(self.attitude_change)

    def exaggerated(self, factor: float) -> tuple[np.ndarray, np.ndarray]:
        """The adjusted trajectory drawn ``factor`` times farther from the original: centres
        ``original + factor * displacement`` (n, 3) metres and attitudes ``change**factor @ original``
        (n, 3, 3) (the change's rotation angle multiplied by ``factor`` about the same axis)."""
        from scipy.spatial.transform import Rotation

        centres = self.original_centre_m + float(factor) * self.displacement_m
        rotvec = Rotation.from_matrix(self.attitude_change).as_rotvec()
        change = Rotation.from_rotvec(float(factor) * rotvec).as_matrix()
        return centres, change @ self.original_attitude

    def summary(self) -> dict[str, Any]:
        """JSON-ready ranges: perspective-centre displacement (m) and attitude change (microradians)."""
        d = np.linalg.norm(self.displacement_m, axis=1)
        a = self.attitude_change_rad * 1e6
        return {"displacement_m": [float(d.min()), float(d.max())], "attitude_change_urad": [float(a.min()),
                                                                                            float(a.max())]}


def trajectory_comparison(original: Any, adjusted: Any, n: int = 25) -> TrajectoryComparison:
    """Sample two line-scan sensors (before / after an adjustment) at ``n`` rows spread over the image.

    Parameters
    ----------
    original, adjusted : LineGeometrySensor
        Sensors with ``has_line_geometry`` (``line_time``, ``perspective_centre``, ``attitude``), same
        frame and image; the rows are timed by the original (an adjustment may move the line times of the
        adjusted one, the comparison is at the same instant).
    n : int
        Samples (>= 2).

    Raises
    ------
    ValueError
        A sensor without line geometry (an RPC: no trajectory).
    """
    from explorer.sensor import has_line_geometry

    for s in (original, adjusted):
        if not has_line_geometry(s):
            raise ValueError(f"a {type(s).__name__} has no scanlines: no trajectory to draw")
    rows = np.linspace(-0.5, float(original.n_rows) - 0.5, max(int(n), 2))
    t = np.asarray(original.line_time(rows), dtype=np.float64)
    return TrajectoryComparison(rows, t, np.asarray(original.perspective_centre(t), dtype=np.float64),
                                np.asarray(adjusted.perspective_centre(t), dtype=np.float64),
                                np.asarray(original.attitude(t), dtype=np.float64),
                                np.asarray(adjusted.attitude(t), dtype=np.float64))


def refinement_trajectory(ref: Refinement, image: int = 0, n: int = 25) -> TrajectoryComparison:
    """The trajectory of image ``image`` of a refinement, before and after (its adapter's adjusted sensor:
    ``adjusted_sensor(model, params)``, else the ``adjusted`` sensor it kept).

    Raises
    ------
    ValueError
        For an image without scanlines (an RPC).
    """
    from explorer.sensor import has_line_geometry

    adapter = ref.images[image]
    if not has_line_geometry(adapter.sensor):
        raise ValueError(f"an {adapter.what} has no trajectory: the 3D view needs a sensor with scanlines")
    make = getattr(adapter, "adjusted_sensor", None)
    # the adapter's adjusted sensor for these parameters, else the one it kept from the adjustment
    adjusted = (make(ref.models[image], ref.result.parameters[image]) if make is not None
                else getattr(adapter, "adjusted", None))
    if adjusted is None:
        raise ValueError(f"the {adapter.what} adapter keeps no adjusted sensor: no trajectory")
    return trajectory_comparison(adapter.sensor, adjusted, n)
