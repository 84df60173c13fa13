"""A best-scanline method behind the :class:`explorer.sensor.Sensor` interface.

:class:`MethodSensor` answers ground to image with a registered method (``exact``, ``nr``, a learned
``lrm`` ...) on a scene, and everything else (image to ground, footprint, times) with the scene's own
model, so code written for a Sensor (orthorectification, :mod:`explorer.ortho`) runs with any method
without knowing it is one.  A method that needs control points is fitted on SCOPs simulated from the
scene itself (its own image to ground, :func:`explorer.points.image_grid`), spanning the heights the
caller will ask for.

Not a method module: it registers nothing (the registry discovers it and finds no method).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np

from explorer.errors import InputError
from explorer.methods.base import BestScanlineMethod, create
from explorer.points import image_grid
from explorer.sensor import Localization, Projection

if TYPE_CHECKING:
    from explorer.geometry.frames import Ellipsoid, LocalFrame
    from explorer.points import PointSet
    from explorer.scene import Scene

#: SCOPs a learned method is fitted on by default (the largest count of the papers' protocol).
DEFAULT_SCOPS = 100

#: Height layers of those SCOPs (a 3-D grid: the learned methods model the height dependence too).
SCOP_LAYERS = 3


class MethodSensor:
    """A scene whose ground to image is a best-scanline method's answer.

    Parameters
    ----------
    scene : Scene
        The model the method runs on; image to ground, footprint and times are its own.
    method : BestScanlineMethod
        A fitted method on ``scene`` (see :meth:`create`).

    ``ground_to_image`` gives NaN where the method's answer is not valid (not converged, off the image,
    outside a learned model's domain): such points are flagged, never returned bare.
    """

    #: The method answers ground to image, not the polynomials; the adapter offers no line geometry of its own.
    has_polynomial_exterior: ClassVar[bool] = False
    has_line_geometry: ClassVar[bool] = False

    def __init__(self, scene: Scene, method: BestScanlineMethod) -> None:
        self.scene = scene
        self.method = method
        self.name = f"{scene.name} ({method.name})"

    @classmethod
    def create(
        cls,
        scene: Scene,
        method: str,
        *,
        params: dict | None = None,
        height_range: tuple[float, float] | None = None,
        scops: int = DEFAULT_SCOPS,
        seed: int = 0,
    ) -> MethodSensor:
        """The method ``method`` (registry name) on ``scene``, fitted when it needs control points.

        Parameters
        ----------
        scene : Scene
        method : str
        params : dict, optional
            Method parameters.
        height_range : (float, float), optional
            Local heights (metres) the SCOPs span (:data:`SCOP_LAYERS` layers); default: the scene terrain's
            range, widened to +-500 m when it is flat (:func:`explorer.points.image_grid`).
        scops : int
            About this many SCOPs per layer (>= 4).
        seed : int
        """
        m = create(method, scene, **(params or {}))
        if m.needs_fit:
            if scops < 4:
                raise InputError(f"{scops} SCOPs: a learned method needs at least 4 control points per layer")
            m.fit(cls.control_points(scene, scops, height_range, seed))
        return cls(scene, m)

    @staticmethod
    def control_points(
        scene: Scene, scops: int, height_range: tuple[float, float] | None = None, seed: int = 0
    ) -> PointSet:
        """SCOPs from the scene's own image to ground: a grid of about ``scops`` image points per layer on
        :data:`SCOP_LAYERS` planes spanning ``height_range`` (local heights, metres)."""
        return image_grid(scene, scops, layers=SCOP_LAYERS, height_range=height_range, seed=seed)

    # ------------------------------------------------------------------ Sensor
    @property
    def frame(self) -> LocalFrame:
        return self.scene.frame

    @property
    def body(self) -> Ellipsoid:
        return self.scene.body

    @property
    def n_rows(self) -> int:
        return self.scene.n_rows

    @property
    def n_columns(self) -> int:
        return self.scene.n_columns

    def ground_to_image(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ground (N, 3), local ENU metres -> (row, col) (N,) by the method; NaN where its answer is not valid."""
        res = self.method.ground_to_image(ground)
        valid = res.valid
        return np.where(valid, res.row, np.nan), np.where(valid, res.col, np.nan)

    def project(self, ground: np.ndarray) -> Projection:
        """(row, col) and the method's validity (converged, on the image, inside a learned model's domain)."""
        res = self.method.ground_to_image(ground)
        return Projection(res.row, res.col, res.valid)

    def geodetic_to_image(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`ground_to_image` of geodetic points (degrees, metres above the ellipsoid; the methods work in the
        scene's local frame: converted to it once)."""
        return self.ground_to_image(self.frame.geodetic_to_enu(lon, lat, h))

    def project_geodetic(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> Projection:
        """:meth:`project` of geodetic points (converted to the scene's local frame once)."""
        return self.project(self.frame.geodetic_to_enu(lon, lat, h))

    def image_to_ground(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> np.ndarray:
        """The scene's own image to ground (a method only maps ground to image)."""
        return self.scene.image_to_ground(row, col, height=height)

    def localize(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> Localization:
        """The scene's own image to ground with flags."""
        return self.scene.localize(row, col, height=height)

    def footprint(self, height: float | None = None) -> np.ndarray:
        return self.scene.footprint(height)

    def time_range(self) -> tuple[float, float]:
        return self.scene.time_range()


__all__ = ["DEFAULT_SCOPS", "SCOP_LAYERS", "MethodSensor"]
