"""Fast collinearity kernels: the along-track residual, its analytic time derivative and the
image column for millions of points, plus the compiled per-point root finders used by the
``exact`` and ``csm-secant`` methods.

The residual is the best-scanline condition of ``docs/conventions.md#best-scanline``
(Ahooei Nezhad et al. 2024, Remote Sensing 16:2787, eqs. 1-2; the MPC model of the same paper):

    v = R(t)^T (P - S(t)),   x = -f v_x / v_z,   y = -f v_y / v_z,
    (x_d, y_d) = (x, y) * F(r^2),   F = 1 + k1 r^2 + k2 r^4 + ...,   r^2 = x^2 + y^2,
    g(t) = x_d - x_det(y_d),   x_det(y) = offset + c1 y + c2 y^2 + ...

with ``S(t)`` and the angles ``(omega, phi, kappa)(t)`` ascending polynomials of any degree plus
jitter sinusoids ``A sin(w t + p)`` and ``R = R_x(omega) R_y(phi) R_z(kappa)``
(``docs/conventions.md#rotations``).  Its time derivative is analytic:

    dv/dt = (dR/dt)^T (P - S) - R^T dS/dt,
    dR/dt = dR/domega omega' + dR/dphi phi' + dR/dkappa kappa'   (chain rule on the closed form),
    dx/dt = (-f / v_z) (v_x' - v_x v_z' / v_z)   (same for y),
    d(r^2)/dt = 2 (x x' + y y'),   x_d' = x' F + x F'(r^2) (r^2)',
    g' = x_d' - x_det'(y_d) y_d',

with ``dS/dt`` the velocity polynomial and the angle rates including the jitter terms
``A w cos(w t + p)``.

Three evaluators of one collinearity evaluation (CE: residual, derivative, column):

* :func:`_collinearity_point_py` with ``fast=False`` -- the reference: the same floating-point
  operations in the same order as :meth:`explorer.scene.Scene.along_track_residual` (bit for bit);
* the same function with ``fast=True`` -- the angle sines by the addition theorem around the
  constant terms with Taylor series of the small increment (:func:`_sincos_near`), one division;
* :func:`_ce_fixed_py` -- branch- and loop-free: polynomials zero-padded to degree 3, up to
  ``JITTER_MAX`` jitter sinusoids from per-scanline tables of ``sin``/``cos`` plus the addition
  theorem, distortion and detector curvature zero-padded to 3 terms.  LLVM vectorises the loop
  over points (AVX2) around it.  It applies when the scene fits (:meth:`CollinearityParams.fixed_model`).

All of them are written with operations valid on scalars and on numpy arrays alike: numba compiles
them for the per-point kernels, and the pure-numpy fallback (numba missing, or
``EXPLORER_DISABLE_NUMBA=1``) calls the very same code on arrays, so both backends perform the same
operations and agree bit for bit (given the same libm).  ``fast`` results differ from the reference
by round-off only (about ``eps |S - P| / GSD``, 1e-10 px), the floor of the model itself.

The solvers (:func:`solve_exact`, :func:`solve_secant`) run the per-point iterations inside
compiled ``prange``-parallel loops (no per-point Python); the numpy fallbacks run the same
algorithms vectorised over points, one Python step per iteration.

Modules (one concern each; this package re-exports the names other modules use):

* :mod:`~explorer.geometry.kernels.params` -- :class:`CollinearityParams`, :class:`FixedModel`, status codes;
* :mod:`~explorer.geometry.kernels.evaluators` -- the per-point CE evaluators (reference, fast, branch-free);
* :mod:`~explorer.geometry.kernels.residual` -- :func:`residual_and_rate`, :func:`columns_at_rows`;
* :mod:`~explorer.geometry.kernels.seed` -- :class:`SeedModel`, :func:`seed_features`;
* :mod:`~explorer.geometry.kernels.exact` -- :func:`solve_exact`;
* :mod:`~explorer.geometry.kernels.secant` -- :func:`solve_secant` (the usgscsm approach);
* :mod:`~explorer.geometry.kernels.threads` -- :func:`set_threads`.
"""

from __future__ import annotations

from explorer._numba import NUMBA_AVAILABLE, njit, prange
from explorer.geometry.kernels.evaluators import (
    _ce_either,
    _ce_fixed,
    _ce_fixed_py,
    _collinearity_point_py,
    _sincos_near,
    _table_index,
    collinearity_point,
)
from explorer.geometry.kernels.exact import (
    _ACCEPTED,
    _NO_ROOT,
    _RUNNING,
    _TO_GENERAL,
    NewtonOptions,
    _dummy_fixed,
    _solve_exact_np,
    solve_exact,
)
from explorer.geometry.kernels.params import (
    FIXED_MAX_TERMS,
    SMALL_ANGLE,
    STATUS_CONVERGED,
    STATUS_INVALID,
    STATUS_MAX_ITER,
    STATUS_NAMES,
    STATUS_NO_ROOT_IN_WINDOW,
    CollinearityParams,
    FixedModel,
)
from explorer.geometry.kernels.residual import (
    COLUMN_WINDOW_MARGIN,
    collinearity_params_or_none,
    columns_at_rows,
    residual_and_rate,
)
from explorer.geometry.kernels.secant import FIXED_MARGIN_ROWS, solve_secant
from explorer.geometry.kernels.seed import SEED_TERMS, SeedModel, _seed_full_py, _seed_row_py, seed_features
from explorer.geometry.kernels.threads import set_threads

__all__ = [
    "COLUMN_WINDOW_MARGIN",
    "FIXED_MARGIN_ROWS",
    "FIXED_MAX_TERMS",
    "NUMBA_AVAILABLE",
    "SEED_TERMS",
    "SMALL_ANGLE",
    "STATUS_CONVERGED",
    "STATUS_INVALID",
    "STATUS_MAX_ITER",
    "STATUS_NAMES",
    "STATUS_NO_ROOT_IN_WINDOW",
    "CollinearityParams",
    "FixedModel",
    "NewtonOptions",
    "SeedModel",
    "collinearity_params_or_none",
    "collinearity_point",
    "columns_at_rows",
    "njit",
    "prange",
    "residual_and_rate",
    "seed_features",
    "set_threads",
    "solve_exact",
    "solve_secant",
    # used by explorer.geometry's Newton and torch solvers (same package family)
    "_ACCEPTED",
    "_NO_ROOT",
    "_RUNNING",
    "_TO_GENERAL",
    "_ce_either",
    "_ce_fixed",
    "_ce_fixed_py",
    "_collinearity_point_py",
    "_dummy_fixed",
    "_seed_full_py",
    "_seed_row_py",
    "_sincos_near",
    "_solve_exact_np",
    "_table_index",
]
