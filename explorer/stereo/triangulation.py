"""Triangulation of matched pixels of two images: :func:`triangulate`.

For each match the two lines of sight are built from each sensor's own localisation (image to ground at two
heights gives a ray, in body-fixed ECEF), their closest approach starts Gauss-Newton on the 3D point, which
minimises the four pixel residuals (row and column in each image) of the sensors' own ground to image, so that
on an exact match the reprojection is exact even where a line of sight is a curve (an RPC's is).  The result
carries the distance of the two lines of sight near the point (``ray_distance_m``: their tangents at the
solution's height, at their closest approach), the reprojection error in each image and flags.

Two RPC sensors (or RPC models) run in one compiled kernel per point (analytic Jacobian of both
projections); any other pair runs vectorised over the points with the sensors' own (compiled) ground to image
and a finite-difference Jacobian, the closest approaches and the 3 x 3 solves compiled.

Flags (``Triangulation.flags``, uint8 bits; ``valid`` is ``flags == 0``; coordinates are NaN where a point
is not valid):

=====  ===================  ===============================================================================
bit    name                 meaning
=====  ===================  ===============================================================================
1      ``OUTSIDE_LEFT``     the left pixel is outside the left image (``docs/conventions.md#pixels``)
2      ``OUTSIDE_RIGHT``    the right pixel is outside the right image
4      ``PARALLEL``         the lines of sight are parallel (angle below ``min_angle_deg``)
8      ``BEHIND``           the point lies behind a sensor's perspective centre (sensors with positions)
16     ``NOT_CONVERGED``    a localisation or the Gauss-Newton iterations did not converge
32     ``OUTSIDE_DOMAIN``   outside an RPC's validity domain (an RPC has no position: a point above the
                            satellite is outside its height domain)
=====  ===================  ===============================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explorer.errors import InputError, check_finite
from explorer.sensor import Sensor
from explorer.stereo import _kernels
from explorer.stereo.sensors import (
    RPC_MAX_ITER,
    as_sensor,
    check_same_body,
    ecef_to_geodetic,
    inside_image,
    localise,
    mean_height,
    perspective_centres,
    project,
    rpc_arrays,
    rpc_model,
)

OUTSIDE_LEFT = _kernels.OUTSIDE_LEFT
OUTSIDE_RIGHT = _kernels.OUTSIDE_RIGHT
PARALLEL = _kernels.PARALLEL
BEHIND = _kernels.BEHIND
NOT_CONVERGED = _kernels.NOT_CONVERGED
OUTSIDE_DOMAIN = _kernels.OUTSIDE_DOMAIN
FLAG_NAMES = {OUTSIDE_LEFT: "outside left image", OUTSIDE_RIGHT: "outside right image", PARALLEL: "parallel rays",
              BEHIND: "behind a sensor", NOT_CONVERGED: "not converged", OUTSIDE_DOMAIN: "outside RPC domain"}

#: Gauss-Newton stops when the step is below this (metres).
TOL_M = 1e-7
#: Gauss-Newton iterations at most.
MAX_ITER = 20
#: Heights of the two ray points either side of the sensors' mean height (m).
RAY_HALF_SPAN_M = 250.0
#: Height step of the tangents of the lines of sight at the solution (m).
TANGENT_DH_M = 10.0
#: Finite-difference step of the generic Jacobian (m).
JACOBIAN_STEP_M = 0.5


@dataclass(frozen=True)
class Triangulation:
    """Triangulated points of N matches.

    Attributes
    ----------
    lon, lat : ndarray, shape (N,)
        Degrees, on the ellipsoid of the body (of the left sensor's frame).
    height : ndarray, shape (N,)
        Metres above that ellipsoid.
    xyz : ndarray, shape (N, 3)
        Body-fixed Cartesian coordinates (ECEF), metres.
    ray_distance_m : ndarray, shape (N,)
        Distance of the two lines of sight at their closest approach near the point, metres.
    reprojection_px : ndarray, shape (N, 2)
        Distance of the point's projection from the given pixel in the left and the right image, pixels.
    flags : ndarray of uint8, shape (N,)
        Bits of the module table; 0 is a good point.
    """

    lon: np.ndarray
    lat: np.ndarray
    height: np.ndarray
    xyz: np.ndarray
    ray_distance_m: np.ndarray
    reprojection_px: np.ndarray
    flags: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """True where no flag is set, shape (N,)."""
        return self.flags == 0

    def __len__(self) -> int:
        return int(self.flags.shape[0])

    def flag_counts(self) -> dict[str, int]:
        """How many points carry each flag (name -> count; only flags that occur)."""
        return {name: int(np.count_nonzero(self.flags & bit)) for bit, name in FLAG_NAMES.items()
                if np.any(self.flags & bit)}


def _pixels(values: Any, name: str) -> np.ndarray:
    arr = np.ascontiguousarray(check_finite(np.atleast_1d(np.asarray(values, dtype=np.float64)), name)).ravel()
    return arr


def triangulate(
    left: Any,
    right: Any,
    left_rows: Any,
    left_cols: Any,
    right_rows: Any,
    right_cols: Any,
    *,
    min_angle_deg: float = 0.01,
    tol_m: float = TOL_M,
    max_iter: int = MAX_ITER,
) -> Triangulation:
    """Triangulate matched pixels of two images.

    Parameters
    ----------
    left, right : Sensor or RationalFunctionModel
        Any two sensors (:class:`explorer.sensor.Sensor`: RPC, rigorous line-scan, CSM, MPC scene) or RPC models
        (:func:`explorer.read_rpc`), each with its own frame; the output is on the left sensor's body.
    left_rows, left_cols, right_rows, right_cols : array_like, shape (N,)
        Matched pixels (0-based, integer = pixel centre, ``docs/conventions.md#pixels``).
    min_angle_deg : float
        Lines of sight meeting at a smaller angle are flagged ``PARALLEL``.
    tol_m, max_iter : float, int
        Gauss-Newton stop (step in metres) and iteration limit.

    Returns
    -------
    Triangulation

    Raises
    ------
    InputError
        A sensor of an unknown type, sensors on two bodies, pixel arrays of different lengths, or a NaN/infinite
        pixel.
    """
    left_s = as_sensor(left, "left")
    right_s = as_sensor(right, "right")
    check_same_body(left_s, right_s)
    lr, lc, rr, rc = (_pixels(v, n) for v, n in ((left_rows, "left_rows"), (left_cols, "left_cols"),
                                                 (right_rows, "right_rows"), (right_cols, "right_cols")))
    if not (lr.size == lc.size == rr.size == rc.size):
        raise InputError(f"matched pixel arrays differ in length: left {lr.size}/{lc.size}, right {rr.size}/{rc.size}")
    if not (0.0 < min_angle_deg < 90.0):
        raise InputError(f"min_angle_deg must be in (0, 90), got {min_angle_deg}")
    min_sin2 = float(np.sin(np.radians(min_angle_deg)) ** 2)
    model_l, model_r = rpc_model(left_s), rpc_model(right_s)
    if model_l is not None and model_r is not None:
        out = _triangulate_rpc_pair(left_s, right_s, lr, lc, rr, rc, min_sin2, tol_m, max_iter)
    else:
        out = _triangulate_generic(left_s, right_s, lr, lc, rr, rc, min_sin2, tol_m, max_iter)
    geo, xyz, ray, rep, flags = out
    flags |= np.where(inside_image(left_s, lr, lc), 0, OUTSIDE_LEFT).astype(np.uint8)
    flags |= np.where(inside_image(right_s, rr, rc), 0, OUTSIDE_RIGHT).astype(np.uint8)
    for model in (model_l, model_r):
        if model is not None:
            ok = model.ground_validity(geo[:, 0], geo[:, 1], geo[:, 2])
            flags |= np.where(ok | ~np.isfinite(geo[:, 0]), 0, OUTSIDE_DOMAIN).astype(np.uint8)
    bad = flags != 0
    geo[bad] = np.nan
    xyz[bad] = np.nan
    ray = np.where(bad, np.nan, ray)
    rep[bad] = np.nan
    return Triangulation(geo[:, 0].copy(), geo[:, 1].copy(), geo[:, 2].copy(), xyz, ray, rep, flags)


def _triangulate_rpc_pair(left: Sensor, right: Sensor, lr: np.ndarray, lc: np.ndarray, rr: np.ndarray,
                          rc: np.ndarray, min_sin2: float, tol_m: float, max_iter: int
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both sensors are RPCs: one compiled kernel per point (WGS84)."""
    model_l, model_r = rpc_model(left), rpc_model(right)
    assert model_l is not None and model_r is not None
    coef_l, norm_l = rpc_arrays(model_l)
    coef_r, norm_r = rpc_arrays(model_r)
    h_mid = 0.5 * (float(model_l.height_offset) + float(model_r.height_offset))
    n = lr.size
    geo = np.empty((n, 3))
    xyz = np.empty((n, 3))
    ray = np.empty(n)
    rep = np.empty((n, 2))
    flags = np.zeros(n, dtype=np.uint8)
    _kernels.rpc_pair_triangulate(coef_l, norm_l, coef_r, norm_r, lr, lc, rr, rc, h_mid - RAY_HALF_SPAN_M,
                                  h_mid + RAY_HALF_SPAN_M, min_sin2, max(int(max_iter), RPC_MAX_ITER), float(tol_m),
                                  TANGENT_DH_M, geo, xyz, ray, rep, flags)
    return geo, xyz, ray, rep, flags


def _rays(sensor: Sensor, row: np.ndarray, col: np.ndarray, h0: float, h1: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Line of sight of each pixel (ECEF): point at ``h0``, vector to the point at ``h1``, ok."""
    p0, ok0 = localise(sensor, row, col, np.full(row.shape, h0))
    p1, ok1 = localise(sensor, row, col, np.full(row.shape, h1))
    return p0, p1 - p0, ok0 & ok1


def _triangulate_generic(left: Sensor, right: Sensor, lr: np.ndarray, lc: np.ndarray, rr: np.ndarray,
                         rc: np.ndarray, min_sin2: float, tol_m: float, max_iter: int
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Any two sensors: vectorised over points with the sensors' own projections."""
    n = lr.size
    flags = np.zeros(n, dtype=np.uint8)
    h_mid = 0.5 * (mean_height(left) + mean_height(right))
    h0, h1 = h_mid - RAY_HALF_SPAN_M, h_mid + RAY_HALF_SPAN_M
    pl, ul, okl = _rays(left, lr, lc, h0, h1)
    pr, ur, okr = _rays(right, rr, rc, h0, h1)
    ok = okl & okr
    flags[~ok] |= NOT_CONVERGED
    pl[~ok] = 0.0
    ul[~ok] = 1.0
    pr[~ok] = 0.0
    ur[~ok] = 1.0
    x, _, sin2, _, _ = _kernels.closest_approach(pl, ul, pr, ur)
    parallel = ok & ~(sin2 >= min_sin2)
    flags[parallel] |= PARALLEL
    active = np.flatnonzero(flags == 0)
    x[flags != 0] = np.nan
    observed = np.stack([lr, lc, rr, rc], axis=1)
    converged = np.zeros(n, dtype=bool)
    steps = np.eye(3) * JACOBIAN_STEP_M
    for _ in range(max_iter):
        if active.size == 0:
            break
        xa = x[active]
        base = _project_pair(left, right, xa)
        jac = np.empty((active.size, 4, 3))
        for k in range(3):
            jac[:, :, k] = (_project_pair(left, right, xa + steps[k]) - base) / JACOBIAN_STEP_M
        res = observed[active] - base
        step = _kernels.solve_normal_3(np.ascontiguousarray(jac), np.ascontiguousarray(res))
        finite = np.isfinite(step).all(axis=1)
        x[active] = xa + np.where(finite[:, None], step, np.nan)
        done = finite & (np.linalg.norm(np.where(finite[:, None], step, 0.0), axis=1) <= tol_m)
        converged[active[done]] = True
        active = active[~done & finite]
    flags[(flags == 0) & ~converged] |= NOT_CONVERGED
    lon, lat, h = ecef_to_geodetic(left, x)
    geo = np.stack([lon, lat, h], axis=1)
    final = _project_pair(left, right, x)
    rep = np.stack([np.hypot(*(final[:, 0:2] - observed[:, 0:2]).T), np.hypot(*(final[:, 2:4] - observed[:, 2:4]).T)],
                   axis=1)
    # tangents of the lines of sight at the solution's height
    good = flags == 0
    ray = np.full(n, np.nan)
    if good.any():
        hg = h[good]
        al, okl2 = localise(left, lr[good], lc[good], hg)
        bl, okl3 = localise(left, lr[good], lc[good], hg + TANGENT_DH_M)
        ar, okr2 = localise(right, rr[good], rc[good], hg)
        br, okr3 = localise(right, rr[good], rc[good], hg + TANGENT_DH_M)
        _, dist, _, _, _ = _kernels.closest_approach(al, bl - al, ar, br - ar)
        ok_t = okl2 & okl3 & okr2 & okr3
        ray[good] = np.where(ok_t, dist, np.nan)
        idx = np.flatnonzero(good)
        flags[idx[~ok_t]] |= NOT_CONVERGED
    # behind a perspective centre: the point must lie on the looking side of each sensor
    for sensor, row, col, u in ((left, lr, lc, ul), (right, rr, rc, ur)):
        good = flags == 0
        if not good.any():
            continue
        centres = perspective_centres(sensor, row[good], col[good])
        if centres is None:
            continue
        look = -u[good]  # u runs from the lower to the higher height: the sensor looks the other way
        behind = np.einsum("ij,ij->i", x[good] - centres, look) <= 0.0
        idx = np.flatnonzero(good)
        flags[idx[behind]] |= BEHIND
    return geo, x, ray, rep, flags


def _project_pair(left: Sensor, right: Sensor, ecef: np.ndarray) -> np.ndarray:
    """(N, 4): left row, left col, right row, right col of ECEF points."""
    lrow, lcol = project(left, ecef)
    rrow, rcol = project(right, ecef)
    return np.stack([lrow, lcol, rrow, rcol], axis=1)


def compile_parallel_twins() -> int:
    """Compile (or load from numba's cache) the other variant -- parallel or serial -- of every stereo kernel for
    each argument type one variant has been compiled for in this process; returns how many were compiled.

    Which variant runs depends on the number of matches (``_kernels.PARALLEL_MIN_POINTS``); the warm-up runs
    small pairs and compiles the parallel variants from their serial twins' signatures (:mod:`explorer.warmup`),
    so a first run on a million matches compiles nothing either."""
    n = 0
    for pair in _kernels.TWINS:
        for disp in pair:
            for other in pair:
                if other is not disp:
                    for sig in list(getattr(disp, "signatures", ())):  # none without numba
                        if sig not in other.signatures:
                            other.compile(sig)
                            n += 1
    return n


__all__ = ["BEHIND", "FLAG_NAMES", "NOT_CONVERGED", "OUTSIDE_DOMAIN", "OUTSIDE_LEFT", "OUTSIDE_RIGHT", "PARALLEL",
           "Triangulation", "compile_parallel_twins", "triangulate"]
