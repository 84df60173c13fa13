"""``csm-secant``: the ground-to-image iteration of the USGS Community Sensor Model line scanner.

A production baseline: ``UsgsAstroLsSensorModel::groundToImage`` of usgscsm (the CSM plug-in used
by ISIS / ASP / ALE for pushbroom cameras, https://github.com/DOI-USGS/usgscsm), restated from its
source for this project's rigorous model:

1. **Projective seed** (``createProjectiveApproximation`` / ``computeProjectiveApproximation``):
   at construction a 3 x 3 image grid -- lines and samples at 0, 1/2 and 1 of the image extent,
   i.e. the image edges and centre (rows ``-0.5, (rows-1)/2, rows-0.5`` in this project's
   pixel-centre convention, ``docs/conventions.md#pixels``) -- is projected to the ground at two
   heights, the scene's mean height ``h`` and ``h + 100 m`` (usgscsm: the reference point's
   ellipsoid height and +100 m), and a projective transform
   ``line = (a0 + a1 X + a2 Y + a3 Z) / (1 + b1 X + b2 Y + b3 Z)`` is fitted by linear least
   squares to the 18 points (usgscsm fits the sample too; only the line is used here).  The
   coordinates are the local ENU metres normalised by their mean and spread (usgscsm uses raw
   ECEF; normalising only improves the conditioning, the model is the same).  The seed is
   clamped to the image, as usgscsm does.
2. **Secant iteration** on the detector-line residual ``e(dt) = (x_d - x_det(y_d)) / pitch``
   (pixels; usgscsm's ``calcDetectorLineErr``) as a function of the line offset ``dt`` from the
   seed: ``e0 = e(0)``, ``e1 = e(0.1)``; while ``|e1| > desired_precision`` and ``++count < 15``:
   stop if ``e1 == e0``, else ``dt2 = dt1 - e1 (dt1 - dt0) / (e1 - e0)``, shift.  The row is
   ``seed + dt1``; the sample comes from one more evaluation at that row.  usgscsm then warns
   ``PRECISION_NOT_MET`` when ``|e1| > desired_precision``; here such points get
   ``converged=False``.  There is no bracket: the method relies on the seed being close and
   the residual nearly linear in time, which holds for the presets.

Tolerance semantics: ``desired_precision`` bounds the *residual* in detector pixels, not the
step; usgscsm's CSM default is 0.001 px, the default here is 1e-9 px (the residual's float
floor is about 1e-10 px), which makes the row exact to ~1e-9 rows.  Each residual evaluation
and the final column evaluation count as one collinearity evaluation (CE).

Compiled with numba (one ``prange`` loop over points, the iteration inside); without numba the
same iteration runs vectorised in numpy.  Only ``device="cpu"`` is supported.

Reference: USGS Astrogeology, usgscsm ``src/UsgsAstroLsSensorModel.cpp`` (groundToImage,
calcDetectorLineErr, computeProjectiveApproximation, createProjectiveApproximation), versions
1.6-2.0.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer.geometry.kernels import CollinearityParams, solve_secant
from explorer.methods._line_geometry import solve_usgscsm_secant
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.methods.exact import check_device
from explorer.scene import Scene
from explorer.sensor import has_polynomial_exterior

PROJECTIVE_FACTORS = (0.0, 0.5, 1.0)  # usgscsm u_factors / v_factors
PROJECTIVE_DELTA_Z = 100.0  # usgscsm delta_z, metres


def fit_projective_line(scene: Scene) -> tuple[np.ndarray, int]:
    """usgscsm's projective approximation of the line, fitted on a 3 x 3 grid at two heights.

    Returns
    -------
    proj : ndarray, shape (14,)
        ``(a0, a1, a2, a3, b1, b2, b3, 0, mean X, Y, Z, scale X, Y, Z)``; the line is
        ``(a0 + a . u) / (1 + b . u)`` with ``u = (P - mean) / scale``.
    n_points : int
        Ground points simulated for the fit (a one-off setup cost).
    """
    f = np.asarray(PROJECTIVE_FACTORS)
    rows = -0.5 + f * scene.n_rows
    cols = -0.5 + f * scene.n_columns
    rr, cc = (a.ravel() for a in np.meshgrid(rows, cols, indexing="ij"))
    h = scene.terrain.mean_height
    ground = np.concatenate([scene.image_to_ground(rr, cc, height=h),
                             scene.image_to_ground(rr, cc, height=h + PROJECTIVE_DELTA_Z)])
    line = np.concatenate([rr, rr])
    ok = np.isfinite(ground).all(axis=1)  # grid points the sensor flags (outside a CSM camera's tables, off body)
    if ok.sum() < 7:
        raise ValueError(f"{scene.name}: only {int(ok.sum())} of the 18 projective-fit points reach the ground")
    ground, line = ground[ok], line[ok]
    mean = ground.mean(axis=0)
    scale = ground.std(axis=0)
    scale[scale == 0] = 1.0
    u = (ground - mean) / scale
    design = np.column_stack([np.ones(line.size), u, -line[:, None] * u])
    coef, *_ = np.linalg.lstsq(design, line, rcond=None)
    proj = np.concatenate([coef, [0.0], mean, scale])
    return proj, int(line.size)


@register
class CsmSecant(BestScanlineMethod):
    """usgscsm line-scanner ``groundToImage``: projective seed + secant on the line residual.

    Parameters
    ----------
    scene : Scene
    desired_precision : float
        Stop when the detector-line residual is at most this many pixels (default 1e-9;
        usgscsm's CSM default is 1e-3).
    max_count : int
        usgscsm's iteration limit (15).
    first_step : float
        Second secant probe, lines after the seed (usgscsm: 0.1).
    backend : {"auto", "numba", "numpy"}
    device : str
        Only "cpu".
    """

    name = "csm-secant"
    label = "usgscsm projective seed + secant"
    reference = (
        "USGS Astrogeology usgscsm, UsgsAstroLsSensorModel::groundToImage "
        "(https://github.com/DOI-USGS/usgscsm)"
    )

    def __init__(
        self,
        scene: Scene,
        *,
        desired_precision: float = 1e-9,
        max_count: int = 15,
        first_step: float = 0.1,
        backend: str = "auto",
        device: str = "cpu",
    ) -> None:
        if not (desired_precision > 0 and max_count >= 1 and first_step != 0):
            raise ValueError("desired_precision must be > 0, max_count >= 1 and first_step != 0")
        super().__init__(scene, desired_precision=desired_precision, max_count=max_count, first_step=first_step,
                         backend=backend, device=device)
        self.device = check_device(self.name, device)
        self.desired_precision = float(desired_precision)
        self.max_count = int(max_count)
        self.first_step = float(first_step)
        self.backend = backend
        # MPC polynomials: the compiled kernel; interpolated tables (rigorous, CSM): the same iteration
        # vectorised over points on the sensor's own residual (explorer.methods._line_geometry)
        self.kernel_params = CollinearityParams.from_scene(scene) if has_polynomial_exterior(scene) else None
        self.proj, self.setup_ce = fit_projective_line(scene)

    def _seed_rows(self, ground: np.ndarray) -> np.ndarray:
        """The projective seed clamped to the image (as the kernel does)."""
        p = self.proj
        u = (ground - p[8:11]) / p[11:14]
        line = (p[0] + u @ p[1:4]) / (1.0 + u @ p[4:7])
        return np.clip(line, -0.5, self.scene.n_rows - 0.5)

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        if self.kernel_params is None:
            row, col, ok, ce = solve_usgscsm_secant(
                self.scene, ground, self._seed_rows(ground), precision=self.desired_precision,
                first_step=self.first_step, max_count=self.max_count)
            rows_trace = None
        else:
            row, col, ok, ce, rows_trace = solve_secant(
                self.kernel_params, ground, self.proj, precision=self.desired_precision, first_step=self.first_step,
                max_count=self.max_count, trace=trace, backend=self.backend,
            )
        estimate = row
        row = np.where(ok, row, np.nan)
        col = np.where(ok, col, np.nan)
        info = {"row_estimate": estimate, "precision_not_met": int(np.count_nonzero(~ok)), "setup_ce": self.setup_ce}
        return self._result(ground, row, ok, ce, col=col, trace=rows_trace, info=info)
