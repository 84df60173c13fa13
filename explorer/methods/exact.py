"""``exact``: seeded, safeguarded Newton on the collinearity residual, compiled per point.

Our own method for exact ground-to-image at close to memory speed.  It solves the same
best-scanline condition as the Newton-Raphson search of Chen & Rau (1993) restated by Ahooei
Nezhad, Valadan Zoej & Jannati (2020, eq. 3) -- the along-track residual
``x_d(t) - x_det(y_d(t)) = 0`` of ``docs/conventions.md#best-scanline`` -- but

1. **seeds** every point with a cheap polynomial ``row(X, Y, Z)`` (degree 1-3 in normalised
   ground coordinates) fitted at construction by least squares on a small 3D image grid the
   method simulates itself from the rigorous model (default 5 x 5 image points x 3 heights:
   the terrain's min / mean / max, widened to +-500 m around the mean on flat terrain, as
   :func:`explorer.points.image_grid` does).  A time-only disturbance such as attitude jitter
   (tens of Hz) is not followed by any low-degree polynomial of the ground coordinates, so the
   seed adds a correction table: the polynomial's error at the first, centre and last columns at
   the mean height, tabulated every 0.25 rows of the polynomial's own row (where it is looked up),
   interpolated linearly in the row and quadratically in the column (a second polynomial
   ``col(X, Y, Z)`` gives the column); used when it exceeds a tenth of ``accept_step``.  On
   ``agile`` it brings the seed from 4.6 rows to 3e-5 (within ``accept_step``).  No SCOPs are needed;
   the grid, the correction rays, the curvature probe below and the orientation test are a one-off
   setup cost counted in ``self.setup_ce``.  When the seed misses most setup points by more than
   ``accept_step`` (below), every point gets two Newton evaluations in the first compiled pass;
2. iterates **Newton** steps with the analytic time derivative of the residual
   (:mod:`explorer.geometry.kernels`: velocity polynomial, chain rule through
   ``R = R_x R_y R_z`` with the angle rates and jitter, radial distortion, curved / displaced
   detector line), one collinearity evaluation (CE) per iteration.  The first steps run as
   compiled, branch-free passes over all unresolved points (vectorised by LLVM; each pass is one
   plain Newton step, clipped to the search window; a point on a window end whose step points
   outward has no root in the window, the residual being monotone);
3. **safeguards** the points still unresolved after 8 evaluations, or whose evaluation was
   unusable, with a per-point bracket.  The residual is monotone in time over a
   scene (its sign of ``dg/drow``, ``orient``, is checked on the setup grid), so each evaluation
   tells on which side of the iterate the root lies and shrinks the bracket, which starts as the
   image window ``[-0.5 - margin, rows - 0.5 + margin]``.  A Newton step that leaves the bracket
   probes the unevaluated window end (so a root beyond the image is detected in one evaluation),
   otherwise bisects; a Newton step that did not halve ``|g|`` is followed by a bisection; a
   derivative of the wrong sign bisects.  It cannot diverge at image edges, under strong
   attitude rates, jitter or relief;
4. **stops** when the Newton step ``delta`` is below ``accept_step`` rows and returns
   ``row + delta``.  Newton's error after that step is ``C delta^2`` with
   ``C = max |g''| / (2 |g'|)`` (rows^-1), measured at setup around the grid points' roots
   (times a safety factor of 4), so ``accept_step = min(sqrt(tol / C), 0.5)`` guarantees a
   truncation error below ``tol`` (default 1e-12 rows).  On the ten paper presets the seed is
   already within ``accept_step``: **one CE per point** (the returned row is the seed plus one
   Newton step), on ``agile`` (strong rates, jitter) too; with relief and jitter two (the jitter's
   effect on the row depends on the height, which the mean-height table does not follow).

The floating-point floor of the residual itself is about ``eps |S - P| / GSD`` (1e-10 px for a
700 km range at 0.5 m GSD), which is where the measured errors against brute-force truth sit.

Points with no sign change in the window, or behind the camera (``v_z >= 0``, e.g. above the
satellite), come back with ``converged=False`` and ``row=NaN``; a root in the margin is returned
and flagged ``inside=False`` by the base class.  The column is the kernel's at the last
evaluation, moved to the returned row by its analytic rate (``|delta| <= accept_step``, so its
error is far below 1e-12 px), at no extra CE.

Everything runs in numba ``prange`` kernels (parallel over points, no per-point Python); without
numba the same algorithm runs vectorised in numpy with identical decisions.  ``device="cuda"`` (or
``backend="torch"`` on the CPU) runs the seed and the Newton passes through torch on that device
(:mod:`explorer.geometry.torch_solver`), the rare safeguarded points on the host.  Timings:
``docs/performance.md``.

References: Chen, L.-C., Rau, J.-Y. (1993), IEEE TGRS 31(6):1243-1252; Ahooei Nezhad, S.S.,
Valadan Zoej, M.J., Jannati, M. (2020), J. Geospatial Information Technology 8(1):23-38;
Ahooei Nezhad et al. (2024), Remote Sensing 16:2787 (collinearity and MPC, eqs. 1-2).
Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explorer.geometry.kernels import (
    STATUS_CONVERGED,
    STATUS_NAMES,
    CollinearityParams,
    SeedModel,
    residual_and_rate,
    seed_features,
    solve_exact,
)
from explorer.methods._line_geometry import residual_slope, solve_bracketed_secant
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.points import image_grid
from explorer.scene import Scene
from explorer.sensor import has_polynomial_exterior

CURVATURE_OFFSETS = np.linspace(-2.0, 2.0, 9)  # rows around each grid root where C is probed
CURVATURE_SAFETY = 4.0
MAX_ACCEPT_STEP = 0.5
CORRECTION_STEP = 0.25  # rows between the nodes of the seed's row-correction table
CORRECTION_PAD = 64.0  # the table extends this many rows beyond the search window


def check_device(name: str, device: str) -> str:
    """These compiled CPU methods accept ``device="cpu"`` only."""
    if str(device).lower() != "cpu":
        raise ValueError(
            f"method {name!r} runs compiled on the CPU (numba) and supports device='cpu' only, got {device!r}"
        )
    return "cpu"


def check_torch_device(name: str, device: str) -> str:
    """A torch device string ("cpu", "cuda", "cuda:1") that exists on this machine, else ``ValueError``."""
    dev = str(device).lower()
    if dev == "cpu":
        return dev
    if not (dev == "cuda" or dev.startswith("cuda:")):
        raise ValueError(f"method {name!r}: device must be 'cpu' or 'cuda[:index]', got {device!r}")
    import torch

    if not torch.cuda.is_available():
        raise ValueError(f"method {name!r}: device {device!r} requested but torch sees no CUDA device here")
    return dev


@register
class Exact(BestScanlineMethod):
    """Seeded, safeguarded Newton on the along-track residual (see the module docstring).

    Parameters
    ----------
    scene : Scene
    seed_degree : int
        Degree (1, 2 or 3) of the seed polynomial ``row(X, Y, Z)`` (default 2).
    seed_grid : (int, int, int)
        Setup grid: about ``seed_grid[0] * seed_grid[1]`` image points per layer (the grid keeps
        the image's aspect ratio) times ``seed_grid[2]`` heights (default (5, 5, 3)).
    tol : float
        Target truncation error of the returned row, rows (default 1e-12).
    max_iter : int
        Evaluations per point before giving up with ``converged=False`` (default 100).
    margin_rows : float
        The search window extends this many rows beyond the image (default 50).
    backend : {"auto", "numba", "numpy", "torch"}
        Compiled kernel (default when numba is installed), the numpy fallback, or torch
        (:func:`explorer.geometry.torch_solver.solve_exact_torch`: the seed and the Newton passes on
        ``device``, the few safeguarded points on the host; same decisions as numpy).
    device : str
        "cpu" (default) or "cuda[:index]"; a CUDA device implies ``backend="torch"``.
    """

    name = "exact"
    label = "Seeded safeguarded Newton (exact)"
    reference = (
        "this project; Newton on the first collinearity component after Chen & Rau (1993), "
        "IEEE TGRS 31(6):1243-1252"
    )

    def __init__(
        self,
        scene: Scene,
        *,
        seed_degree: int = 2,
        seed_grid: tuple[int, int, int] = (5, 5, 3),
        tol: float = 1e-12,
        max_iter: int = 100,
        margin_rows: float = 50.0,
        backend: str = "auto",
        device: str = "cpu",
    ) -> None:
        if seed_degree not in (1, 2, 3):
            raise ValueError(f"seed_degree must be 1, 2 or 3, got {seed_degree}")
        if not (tol > 0 and max_iter >= 2 and margin_rows >= 0):
            raise ValueError("tol must be > 0, max_iter >= 2 and margin_rows >= 0")
        if len(seed_grid) != 3 or min(seed_grid) < 1 or seed_grid[0] * seed_grid[1] < 4:
            raise ValueError(f"seed_grid must be (rows, cols, layers) with rows*cols >= 4, got {seed_grid}")
        super().__init__(scene, seed_degree=seed_degree, seed_grid=tuple(seed_grid), tol=tol, max_iter=max_iter,
                         margin_rows=margin_rows, backend=backend, device=device)
        if backend not in ("auto", "numba", "numpy", "torch"):
            raise ValueError(f"backend must be 'auto', 'numba', 'numpy' or 'torch', got {backend!r}")
        self.device = check_torch_device(self.name, device)
        if self.device != "cpu":
            backend = "torch"
        self.seed_degree = int(seed_degree)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.margin_rows = float(margin_rows)
        self.backend = backend
        self.host_backend = "auto" if backend == "torch" else backend  # setup, traces, safeguarded points
        self.window = (-0.5 - self.margin_rows, scene.n_rows - 0.5 + self.margin_rows)
        self.setup_ce = 0
        gx, gy, gz = (int(v) for v in seed_grid)
        self.kernel_params: CollinearityParams | None = None
        if has_polynomial_exterior(scene):
            self.kernel_params = CollinearityParams.from_scene(scene)
            self._setup((gx, gy, gz))
        else:  # interpolated tables (rigorous DIMAP / DG, CSM camera): the line-geometry solver
            self._setup_lines((gx, gy, gz))

    def _setup_lines(self, seed_grid: tuple[int, int, int]) -> None:
        """Seed polynomial and residual slope for :func:`explorer.methods._line_geometry.solve_bracketed_secant`."""
        scene = self.scene
        grid = image_grid(scene, seed_grid[0] * seed_grid[1], layers=seed_grid[2])
        ground = grid.ground
        mean = ground.mean(axis=0)
        scale = ground.std(axis=0)
        scale[scale == 0] = 1.0
        design = seed_features((ground - mean) / scale, self.seed_degree)
        if len(grid) < design.shape[1]:
            raise ValueError(f"seed_grid gives {len(grid)} points, fewer than the {design.shape[1]} seed coefficients")
        coef, *_ = np.linalg.lstsq(design, grid.row, rcond=None)
        self.seed_fit_rms_rows = float(np.sqrt(np.mean((design @ coef - grid.row) ** 2)))
        self._line_seed = (mean, scale, coef)
        self.slope = residual_slope(scene, ground, grid.row)
        self.orient = float(np.sign(self.slope))
        self.setup_ce += len(grid) * 3

    # ------------------------------------------------------------------ setup
    def _setup(self, seed_grid: tuple[int, int, int]) -> None:
        scene = self.scene
        grid = image_grid(scene, seed_grid[0] * seed_grid[1], layers=seed_grid[2])
        self.setup_ce += len(grid)  # one image -> ground ray per grid point
        ground = grid.ground
        n_feat = {1: 4, 2: 10, 3: 20}[self.seed_degree]
        if len(grid) < n_feat:
            raise ValueError(f"seed_grid gives {len(grid)} points, fewer than the {n_feat} seed coefficients")
        mean = ground.mean(axis=0)
        scale = ground.std(axis=0)
        scale[scale == 0] = 1.0
        design = seed_features((ground - mean) / scale, self.seed_degree)
        coef, *_ = np.linalg.lstsq(design, grid.row, rcond=None)
        self.seed_fit_rms_rows = float(np.sqrt(np.mean((design @ coef - grid.row) ** 2)))
        poly = SeedModel(mean, scale, coef)
        # orientation of the residual and Newton's curvature constant around the roots
        p = self.kernel_params
        assert p is not None
        n = len(grid)
        rows = (grid.row[None, :] + CURVATURE_OFFSETS[:, None]).ravel()
        pts = np.tile(ground, (CURVATURE_OFFSETS.size, 1))
        g, g_t, _ = residual_and_rate(p, pts, scene.scanline_time(rows), backend=self.host_backend)
        self.setup_ce += rows.size
        g_r = (g_t * p.line_period).reshape(CURVATURE_OFFSETS.size, n)
        signs = np.sign(g_r)
        if not (np.all(signs > 0) or np.all(signs < 0)):
            raise ValueError(f"{scene.name}: the along-track residual is not monotone in time near the image; "
                             "the exact method needs dg/drow of one sign")
        self.orient = float(signs[0, 0])
        h = CURVATURE_OFFSETS[1] - CURVATURE_OFFSETS[0]
        g_rr = np.diff(g_r, axis=0) / h
        mid = 0.5 * (g_r[1:] + g_r[:-1])
        c = float(np.max(np.abs(g_rr) / (2.0 * np.abs(mid))))
        self.curvature_c = CURVATURE_SAFETY * max(c, 1e-300)
        self.accept_step = float(min(np.sqrt(self.tol / self.curvature_c), MAX_ACCEPT_STEP))
        # row correction for time-only disturbances (jitter): the polynomial's error at three columns
        # (first, centre, last) at the mean height, over the search window, resampled onto a uniform grid
        # of the polynomial's own row (the lookup happens at that row)
        col_coef, *_ = np.linalg.lstsq(design, grid.col, rcond=None)
        c_mid = c_half = (scene.n_columns - 1) / 2.0
        rows = np.arange(self.window[0] - CORRECTION_PAD, self.window[1] + CORRECTION_PAD, CORRECTION_STEP)
        poly_rows, errors = [], []
        for c in (c_mid - c_half, c_mid, c_mid + c_half):
            line = scene.image_to_ground(rows, np.full(rows.size, c), height=scene.terrain.mean_height)
            rp = poly.rows(line)
            poly_rows.append(rp)
            errors.append(rows - rp)
        self.setup_ce += 3 * rows.size
        self.seed_correction_max_rows = float(max(np.max(np.abs(h)) for h in errors))
        monotone = all(np.all(np.diff(rp) > 0) for rp in poly_rows)
        if self.seed_correction_max_rows > 0.1 * self.accept_step and monotone:
            r0 = max(rp[0] for rp in poly_rows)
            nodes = np.arange(r0, min(rp[-1] for rp in poly_rows), CORRECTION_STEP)
            table = np.column_stack([np.interp(nodes, rp, h) for rp, h in zip(poly_rows, errors, strict=True)])
            self.seed = SeedModel(mean, scale, coef, table, float(nodes[0]), CORRECTION_STEP, col_coef, c_mid, c_half)
        else:
            self.seed = poly
        # when the seed is mostly farther than accept_step from the root (strong jitter), every point
        # needs a second Newton evaluation: do both in the first compiled pass
        # (judged on the grid points at heights the terrain has: on flat terrain the +-500 m layers only
        # stabilise the fit)
        terrain = scene.terrain
        real = (ground[:, 2] >= terrain.min_height - 1e-6) & (ground[:, 2] <= terrain.max_height + 1e-6)
        miss = np.abs(self.seed.rows(ground[real]) - grid.row[real]) > self.accept_step
        self.first_evaluations = 2 if np.mean(miss) > 0.5 else 1

    # ------------------------------------------------------------------ locate
    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        if self.kernel_params is None:
            return self._locate_lines(ground)
        kw: dict[str, Any] = {"window": self.window, "orient": self.orient, "tol": self.tol,
                              "accept_step": self.accept_step, "max_iter": self.max_iter,
                              "first_evaluations": self.first_evaluations}
        if self.backend == "torch" and not trace:
            from explorer.geometry.torch_solver import solve_exact_torch

            row, col, status, ce = solve_exact_torch(self.kernel_params, ground, self.seed, device=self.device, **kw)
            rows_trace = None
        else:  # traces come from the numpy / numba solver
            row, col, status, ce, rows_trace = solve_exact(
                self.kernel_params, ground, self.seed, trace=trace, backend=self.host_backend, **kw
            )
        converged = status == STATUS_CONVERGED
        counts = {STATUS_NAMES[k]: int(np.count_nonzero(status == k)) for k in STATUS_NAMES}
        info = {"status": status, "status_counts": counts, "setup_ce": self.setup_ce,
                "accept_step_rows": self.accept_step, "curvature_c": self.curvature_c}
        return self._result(ground, row, converged, ce, col=col, trace=rows_trace, info=info)

    def _locate_lines(self, ground: np.ndarray) -> ScanlineResult:
        """Seed + bracketed secant on the sensor's own residual (:mod:`explorer.methods._line_geometry`)."""
        mean, scale, coef = self._line_seed
        seed = seed_features((ground - mean) / scale, self.seed_degree) @ coef
        # the step tolerance: 100 tol, not below the rows to which the sensor's residual defines a root (a rigorous
        # DIMAP / DG model declares 1e-8: asking 1e-10 there cost 7.5 evaluations per point instead of 4.0, for
        # the same distance to the sensor's own ground to image, 4e-9 rows, measured on 50,000 DIMAP SCPs)
        tol = max(min(1e-10, self.tol * 100), float(getattr(self.scene, "root_resolution_rows", 0.0)))
        row, col, status, ce = solve_bracketed_secant(self.scene, ground, seed, window=self.window, slope=self.slope,
                                                      tol=tol, max_iter=self.max_iter)
        counts = {STATUS_NAMES[k]: int(np.count_nonzero(status == k)) for k in STATUS_NAMES}
        info = {"status": status, "status_counts": counts, "setup_ce": self.setup_ce,
                "solver": "line-geometry bracketed secant"}
        return self._result(ground, row, status == STATUS_CONVERGED, ce, col=col, info=info)
