"""Bundle adjustment: Levenberg-Marquardt over image parameters and ground points, Schur complement.

Unknowns are the correction parameters of every image (a few each) and the ground points that are not
fixed (tie points, and control points with a stated ground sigma).  Each image observation ties one
image to one ground point, so the normal matrix is an arrowhead: a small dense block over the image
parameters (``U``), 3 x 3 blocks per ground point (``V_j``) and the couplings (``W_j``).  Each step
eliminates the ground blocks (the reduced camera system ``S = U - sum_j W_j V_j^-1 W_j^T``, a matrix
of the size of the image parameters), solves it, and back-substitutes the ground corrections: the cost
grows linearly with the number of points, never with a dense matrix over them.

Observations and weights (stated, never guessed):

- image observations: ``(measured - projected) / sigma_px`` per coordinate, pixels;
- ground priors of control points: ``(ground - surveyed) / sigma_ground_m`` per axis (east, north, up,
  metres on the body's ellipsoid); a sigma of 0 fixes the point, infinity frees it (a tie point).

The robust loss acts on the whitened 2-D residual of each image observation, ``s = |e|``:
``huber`` (``rho = s^2/2`` up to ``s = c``, linear beyond), ``cauchy`` (``rho = c^2/2 log(1 + s^2/c^2)``)
or ``linear`` (least squares), ``c`` the stated ``loss_scale`` in sigmas.  It is solved by iteratively
reweighted Gauss-Newton steps inside Levenberg-Marquardt.  After it converges, an observation with
``s^2`` above the chi-square (2 degrees of freedom) quantile ``outlier_probability`` is flagged an
outlier -- in units of the stated sigma, or of the robust a posteriori sigma (``median(s^2) / (2 ln 2)``)
where that is larger, so that a model too poor for the data (or too optimistic a sigma) flags nothing and
says so by its ``sigma0`` -- (and a tie point left in a single image by its outliers is dropped whole, its other
observations flagged too); the flagged observations are dropped and a last least-squares pass gives the estimate,
the a posteriori ``sigma0`` and the covariances (``sigma0^2 S^-1`` for the parameters, the blocks
``sigma0^2 (V_j^-1 + V_j^-1 W_j^T S^-1 W_j V_j^-1)`` for the ground points).

Ground points are parametrised by metric offsets from their prior position (east, north, up):
``lon = lon0 + dE / m_lon``, ``lat = lat0 + dN / m_lat``, ``h = h0 + dU`` with ``m_lon``, ``m_lat`` the
metres per degree at the prior position -- an exact reparametrisation of (lon, lat, h), metric to 1e-6.
Jacobians are torch autograd derivatives of the projection (one backward pass per image coordinate); a
projector with ``project_jacobian`` (the line scanners, :mod:`explorer.refine.torch_linescan`) forms its own from
one forward and two backward passes.  Each trial step is evaluated with its linearisation, which the accepted step
keeps for the next iteration: one evaluation per iteration where most steps are accepted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from explorer.errors import ConvergenceError, InputError

__all__ = ["BundleProblem", "BundleResult", "Projector", "bundle_adjust", "lm_iteration", "metres_per_degree",
           "robust_weights"]

WGS84_AXES = (6378137.0, 6356752.314245179)

#: Relative cost changes at or below this are float64 noise for a projector whose ground to image is an iterative
#: line search (its ``cost_rounding``): the compiled search of a rigorous line scanner defines each projection to
#: ~1e-9 px, which moves the cost by ~1e-10 of it (measured on 300 and 10,000 GCPs); a parameter change that moves
#: the cost by 1e-9 of it is below 1e-2 of its sigma.  A closed-form projector (an RPC) declares none: its cost is
#: exact to float64, and the rule below would stop it short of the closed-form solution (1e-8 of the parameters).
COST_ROUNDING = 1e-9

#: Robust losses by name.
LOSSES = ("huber", "cauchy", "linear")
#: The robust pass of :func:`bundle_adjust` stops when an iteration lowers the cost by less than this per
#: observation used (half a chi-square: residuals moving by ~0.01 sigma on average), far below what moves a
#: residual across the outlier threshold; the least-squares pass that gives the estimate converges to rounding.
#: Reweighting converges linearly: on the Pleiades line-scanner pair it crawled at ~1.5e-5 per observation and
#: iteration over tens of iterations (tie points' ground sliding millimetres, nearly collinear position and
#: attitude offsets), with 600 and with 6,000 observations alike -- a tolerance on the whole cost did not scale.
ROBUST_COST_TOLERANCE = 1e-4


class Projector(Protocol):
    """A differentiable ground to image of one image (e.g. :class:`explorer.refine.torch_rpc.TorchRPC`)."""

    parameter_names: tuple[str, ...]

    def project(self, lon: Any, lat: Any, h: Any, params: Any) -> tuple[Any, Any]:
        """torch tensors (N,) of degrees, degrees, metres and parameters (N, P) -> (row, col) (N,)."""
        ...


def metres_per_degree(lat_deg: np.ndarray, h: np.ndarray,
                      axes: tuple[float, float] = WGS84_AXES) -> tuple[np.ndarray, np.ndarray]:
    """Metres per degree of longitude and of latitude at geodetic latitude/height on an ellipsoid (a, b)."""
    a, b = axes
    e2 = 1.0 - (b * b) / (a * a)
    s = np.sin(np.radians(lat_deg))
    w = np.sqrt(1.0 - e2 * s * s)
    n = a / w
    m = a * (1.0 - e2) / w**3
    return (n + h) * np.cos(np.radians(lat_deg)) * (np.pi / 180.0), (m + h) * (np.pi / 180.0)


def robust_weights(s: np.ndarray, loss: str, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """IRLS weights ``rho'(s)/s`` and the loss ``rho(s)`` of whitened residual norms ``s`` (N,)."""
    if loss == "linear":
        return np.ones_like(s), 0.5 * s * s
    if loss == "huber":
        inside = s <= scale
        w = np.where(inside, 1.0, scale / np.maximum(s, 1e-300))
        return w, np.where(inside, 0.5 * s * s, scale * s - 0.5 * scale * scale)
    if loss == "cauchy":
        q = (s / scale) ** 2
        return 1.0 / (1.0 + q), 0.5 * scale * scale * np.log1p(q)
    raise InputError(f"unknown robust loss {loss!r} (one of {', '.join(LOSSES)})")


@dataclass
class BundleProblem:
    """Images, ground points and observations of one adjustment.

    Parameters
    ----------
    projectors : list of Projector
        One per image.
    initial_parameters : list of ndarray
        Start values, one (P_k,) array per image.
    ground : ndarray, shape (M, 3)
        Prior / initial ground points: longitude, latitude (degrees), height (metres).
    ground_sigma_m : ndarray, shape (M, 3)
        East, north, up sigmas of the ground priors, metres: 0 fixes the point, ``inf`` frees it.
    image_index, point_index : ndarray of int, shape (N,)
        Image and ground point of each observation.
    measured : ndarray, shape (N, 2)
        Measured (row, col), pixels.
    sigma_px : ndarray, shape (N,)
        Stated sigma of each coordinate of each observation, pixels.
    axes : (a, b)
        Ellipsoid of the ground coordinates, metres (WGS84 by default).
    """

    projectors: list[Any]
    initial_parameters: list[np.ndarray]
    ground: np.ndarray
    ground_sigma_m: np.ndarray
    image_index: np.ndarray
    point_index: np.ndarray
    measured: np.ndarray
    sigma_px: np.ndarray
    axes: tuple[float, float] = WGS84_AXES

    def __post_init__(self) -> None:
        self.ground = np.asarray(self.ground, dtype=np.float64).reshape(-1, 3)
        m = self.ground.shape[0]
        self.ground_sigma_m = np.broadcast_to(np.asarray(self.ground_sigma_m, dtype=np.float64), (m, 3)).copy()
        self.image_index = np.asarray(self.image_index, dtype=np.int64).ravel()
        self.point_index = np.asarray(self.point_index, dtype=np.int64).ravel()
        self.measured = np.asarray(self.measured, dtype=np.float64).reshape(-1, 2)
        n = self.measured.shape[0]
        self.sigma_px = np.broadcast_to(np.asarray(self.sigma_px, dtype=np.float64), (n,)).copy()
        self.initial_parameters = [np.asarray(p, dtype=np.float64).ravel() for p in self.initial_parameters]
        for name, values in (("ground", self.ground), ("measured", self.measured)):
            if not np.isfinite(values).all():
                raise InputError(f"{name} contains NaN or infinite values")
        if np.isnan(self.ground_sigma_m).any() or (self.ground_sigma_m < 0).any():
            raise InputError("ground sigmas must be >= 0 (0 fixes a point, inf frees it)")
        if not (np.isfinite(self.sigma_px).all() and (self.sigma_px > 0).all()):
            raise InputError("pixel sigmas must be finite and > 0")
        if len(self.projectors) != len(self.initial_parameters):
            raise InputError("one set of initial parameters per image is needed")
        if self.image_index.shape != (n,) or self.point_index.shape != (n,):
            raise InputError("image_index and point_index need one entry per observation")
        if n and (self.image_index.min() < 0 or self.image_index.max() >= len(self.projectors)):
            raise InputError("an observation names an image that does not exist")
        if n and (self.point_index.min() < 0 or self.point_index.max() >= m):
            raise InputError("an observation names a ground point that does not exist")
        pairs = self.image_index * max(m, 1) + self.point_index
        if np.unique(pairs).size != n:
            raise InputError("a ground point is measured twice in the same image")

    @property
    def offsets(self) -> np.ndarray:
        """Column offsets of each image's parameters in the stacked parameter vector, (n_images + 1,)."""
        return np.concatenate([[0], np.cumsum([p.size for p in self.initial_parameters])]).astype(np.int64)


@dataclass
class BundleResult:
    """Outcome of :func:`bundle_adjust` (pixels, metres, degrees as in :class:`BundleProblem`)."""

    parameters: list[np.ndarray]
    parameter_covariance: np.ndarray
    sigma0: float
    redundancy: int
    ground: np.ndarray
    ground_covariance_m: np.ndarray
    residuals_before: np.ndarray
    residuals_after: np.ndarray
    outlier: np.ndarray
    iterations: int
    converged: bool
    cost_history: list[float] = field(default_factory=list)

    @property
    def parameter_sigma(self) -> np.ndarray:
        """Standard deviations of the stacked parameters, (P,)."""
        return np.sqrt(np.clip(np.diag(self.parameter_covariance), 0.0, None))

    @property
    def parameter_correlation(self) -> np.ndarray:
        """Correlation matrix of the stacked parameters, (P, P)."""
        s = self.parameter_sigma
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.parameter_covariance / np.outer(s, s)


class _State:
    """Current unknowns: parameters (stacked) and ground offsets (M, 3) metres from the priors."""

    def __init__(self, theta: np.ndarray, offsets_m: np.ndarray) -> None:
        self.theta = theta
        self.offsets_m = offsets_m


class _Linearisation:
    __slots__ = ("e", "a_theta", "a_x")

    def __init__(self, e: np.ndarray, a_theta: list[np.ndarray], a_x: np.ndarray) -> None:
        self.e = e  # whitened residuals (N, 2)
        self.a_theta = a_theta  # per image: (n_k, 2, P_k) whitened d(projection)/d(theta)
        self.a_x = a_x  # (N, 2, 3) whitened d(projection)/d(ground offset, metres)


def _ground_geodetic(problem: BundleProblem, scale: tuple[np.ndarray, np.ndarray], offsets_m: np.ndarray) -> np.ndarray:
    g = problem.ground
    return np.stack([g[:, 0] + offsets_m[:, 0] / scale[0], g[:, 1] + offsets_m[:, 1] / scale[1],
                     g[:, 2] + offsets_m[:, 2]], axis=1)


def _evaluate(problem: BundleProblem, scale: tuple[np.ndarray, np.ndarray], state: _State,
              jacobians: bool, strict: bool = True) -> tuple[np.ndarray, _Linearisation | None]:
    """Projections (N, 2) of every observation and, with ``jacobians``, the whitened linearisation.

    torch runs on one thread here: its element-wise kernels over 50,000 points took 16 ms forward and
    20 ms backward on one thread, 0.3-0.7 s on two threads of the shared 2-core machine (thread
    hand-over under load).
    """
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        projected, lin = _evaluate_torch(problem, scale, state, jacobians)
    finally:
        torch.set_num_threads(threads)
    if jacobians and strict and not np.isfinite(projected).all():  # (a trial step without one: rejected by its cost)
        k = int(np.flatnonzero(~np.isfinite(projected).all(axis=1))[0])
        raise InputError(f"observation {k} (image {problem.image_index[k]}, ground point {problem.point_index[k]}) "
                         "has no projection: the sensor sees its ground point on no image line (outside the image, "
                         "behind the sensor or outside its ephemeris tables)")
    return projected, lin


def _evaluate_torch(problem: BundleProblem, scale: tuple[np.ndarray, np.ndarray], state: _State,
                    jacobians: bool) -> tuple[np.ndarray, _Linearisation | None]:
    import torch

    ground = _ground_geodetic(problem, scale, state.offsets_m)
    offs = problem.offsets
    n = problem.measured.shape[0]
    projected = np.empty((n, 2))
    a_x = np.zeros((n, 2, 3))
    a_theta: list[np.ndarray] = []
    for k, projector in enumerate(problem.projectors):
        sel = np.flatnonzero(problem.image_index == k)
        pts = problem.point_index[sel]
        lon = torch.from_numpy(ground[pts, 0].copy())
        lat = torch.from_numpy(ground[pts, 1].copy())
        h = torch.from_numpy(ground[pts, 2].copy())
        theta = torch.from_numpy(np.repeat(state.theta[None, offs[k]:offs[k + 1]], sel.size, axis=0))
        if not jacobians:
            with torch.no_grad():
                row, col = projector.project(lon, lat, h, theta)
            projected[sel, 0], projected[sel, 1] = row.numpy(), col.numpy()
            continue
        if hasattr(projector, "project_jacobian"):  # the projector forms its own Jacobians (line scanners)
            row_np, col_np, j_ground, j_params = projector.project_jacobian(
                ground[pts, 0], ground[pts, 1], ground[pts, 2], state.theta[offs[k]:offs[k + 1]])
            projected[sel, 0], projected[sel, 1] = row_np, col_np
            a_x[sel] = j_ground / np.stack([scale[0][pts], scale[1][pts], np.ones(sel.size)], axis=1)[:, None, :]
            a_theta.append(j_params / problem.sigma_px[sel, None, None])
            continue
        # one leaf per observation (its own copy of the ground point and of the parameters): the
        # gradient of the sum of rows is then the per-observation derivative
        d = torch.zeros((sel.size, 3), dtype=torch.float64, requires_grad=True)
        theta.requires_grad_(True)
        m_lon = torch.from_numpy(scale[0][pts])
        m_lat = torch.from_numpy(scale[1][pts])
        row, col = projector.project(lon + d[:, 0] / m_lon, lat + d[:, 1] / m_lat, h + d[:, 2], theta)
        projected[sel, 0], projected[sel, 1] = row.detach().numpy(), col.detach().numpy()
        jt = np.empty((sel.size, 2, offs[k + 1] - offs[k]))
        for c, value in enumerate((row, col)):
            g_d, g_t = torch.autograd.grad(value.sum(), (d, theta), retain_graph=c == 0, allow_unused=True)
            a_x[sel, c] = g_d.numpy() if g_d is not None else 0.0
            jt[:, c] = g_t.numpy() if g_t is not None else 0.0
        a_theta.append(jt / problem.sigma_px[sel, None, None])
    if not jacobians:
        return projected, None
    e = (problem.measured - projected) / problem.sigma_px[:, None]
    return projected, _Linearisation(e, a_theta, a_x / problem.sigma_px[:, None, None])


def _cost(problem: BundleProblem, e: np.ndarray, state: _State, use: np.ndarray, loss: str, scale: float,
          prior_weight: np.ndarray) -> float:
    _, rho = robust_weights(np.hypot(e[:, 0], e[:, 1]), loss, scale)
    prior = 0.5 * float(np.sum(prior_weight * state.offsets_m**2))
    return float(np.sum(rho[use])) + prior


def _normal_equations(problem: BundleProblem, lin: _Linearisation, w: np.ndarray, state: _State,
                      free: np.ndarray, prior_weight: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                         np.ndarray, np.ndarray]:
    """U (P, P), g_theta (P,), V (M, 3, 3), G = W_j (M, P, 3), g_x (M, 3) of weights ``w`` (N,)."""
    offs = problem.offsets
    p_total = int(offs[-1])
    m = problem.ground.shape[0]
    u = np.zeros((p_total, p_total))
    g_theta = np.zeros(p_total)
    v = np.zeros((m, 3, 3))
    big_g = np.zeros((m, p_total, 3))
    g_x = np.zeros((m, 3))
    we = lin.e * w[:, None]
    wax = lin.a_x * w[:, None, None]
    pts_all = problem.point_index
    np.add.at(v, pts_all, np.matmul(wax.transpose(0, 2, 1), lin.a_x))
    np.add.at(g_x, pts_all, np.matmul(lin.a_x.transpose(0, 2, 1), we[:, :, None])[:, :, 0])
    for k in range(len(problem.projectors)):
        sel = np.flatnonzero(problem.image_index == k)
        a = lin.a_theta[k]
        sl = slice(int(offs[k]), int(offs[k + 1]))
        flat = a.reshape(-1, a.shape[2])
        u[sl, sl] += (flat * np.repeat(w[sel], 2)[:, None]).T @ flat
        g_theta[sl] += flat.T @ we[sel].reshape(-1)
        big_g[pts_all[sel], sl, :] += np.matmul(a.transpose(0, 2, 1), wax[sel])  # one observation per (image, point)
    v += prior_weight[:, :, None] * np.eye(3)[None]
    g_x -= prior_weight * state.offsets_m
    fixed = ~free
    v[fixed] = np.eye(3)
    big_g[fixed] = 0.0
    g_x[fixed] = 0.0
    return u, g_theta, v, big_g, g_x


def _reduced_system(u: np.ndarray, g_theta: np.ndarray, v: np.ndarray, big_g: np.ndarray, g_x: np.ndarray,
                    damping: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Damped Schur complement: S (P, P), its right-hand side, V^-1 (M, 3, 3) and T = W V^-1 (M, P, 3)."""
    vd = v + damping * (np.diagonal(v, axis1=1, axis2=2)[:, :, None] * np.eye(3)[None])
    v_inv = np.linalg.inv(vd)
    t = np.matmul(big_g, v_inv)
    p = u.shape[0]
    schur = t.transpose(1, 0, 2).reshape(p, -1) @ big_g.transpose(1, 0, 2).reshape(p, -1).T
    s = u + damping * np.diag(np.diag(u)) - schur
    rhs = g_theta - np.tensordot(t, g_x, axes=([0, 2], [0, 1]))
    return s, rhs, v_inv, t


def _solve_equilibrated(s: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.clip(np.diag(s), 1e-300, None))
    return np.linalg.solve(s / np.outer(d, d), rhs / d) / d


def _check_determined(problem: BundleProblem, s: np.ndarray, names: list[str]) -> None:
    """InputError naming the parameters the observations do not determine (a degenerate configuration)."""
    d = np.sqrt(np.diag(s))
    if (d <= 0).any() or not np.isfinite(d).all():
        bad = [names[i] for i in np.flatnonzero(~(d > 0))]
        raise InputError(f"degenerate configuration: no observation constrains {', '.join(bad)}")
    eq = s / np.outer(d, d)
    eigenvalues, vectors = np.linalg.eigh(eq)
    if eigenvalues[0] < 1e-10 * max(eigenvalues[-1], 1.0):
        null = vectors[:, 0]
        involved = [names[i] for i in np.argsort(-np.abs(null))[:3] if abs(null[i]) > 0.2]
        raise InputError("degenerate configuration: the points do not determine "
                         f"{' / '.join(involved)} (condition {eigenvalues[-1] / max(eigenvalues[0], 1e-300):.1e}; "
                         "spread the points over the image or choose a simpler model)")


def _lm(problem: BundleProblem, scale: tuple[np.ndarray, np.ndarray], state: _State, use: np.ndarray,
        free: np.ndarray, prior_weight: np.ndarray, loss: str, loss_scale: float, max_iterations: int,
        names: list[str], history: list[float], cost_tolerance: float = 0.0) -> tuple[_State, int, bool]:
    """Levenberg-Marquardt from ``state`` on the observations ``use``; returns the state, iterations, converged.

    It stops when an iteration lowers the cost by no more than ``1e-12`` of it or ``cost_tolerance`` (in units of
    the whitened cost, half a chi-square), when the step is below rounding, or when a trial step for which the
    linearisation predicts a decrease below ``1e-6`` of the cost raises it by no more than the projectors' cost
    rounding (their largest ``cost_rounding``, e.g. :data:`COST_ROUNDING` for a line scanner; none for closed-form
    projectors) of it: at the minimum, to the cost's float64 noise (without this rule a line scanner's adjustment
    spent ~15 more evaluations raising the damping to its limit at the end of every run)."""
    damping = 1e-4
    rounding = max((float(getattr(p, "cost_rounding", 0.0)) for p in problem.projectors), default=0.0)
    _, lin = _evaluate(problem, scale, state, True)
    assert lin is not None
    cost = _cost(problem, lin.e, state, use, loss, loss_scale, prior_weight)
    history.append(cost)
    first = True
    for iteration in range(1, max_iterations + 1):
        s_norm = np.hypot(lin.e[:, 0], lin.e[:, 1])
        w = robust_weights(s_norm, loss, loss_scale)[0] * use
        u, g_theta, v, big_g, g_x = _normal_equations(problem, lin, w, state, free, prior_weight)
        if first:
            _check_determined(problem, _reduced_system(u, g_theta, v, big_g, g_x, 0.0)[0], names)
            first = False
        while True:
            s, rhs, v_inv, t = _reduced_system(u, g_theta, v, big_g, g_x, damping)
            step_theta = _solve_equilibrated(s, rhs)
            reduced = g_x - np.tensordot(big_g, step_theta, axes=([1], [0]))
            step_x = np.matmul(v_inv, reduced[:, :, None])[:, :, 0]
            step_x[~free] = 0.0
            trial = _State(state.theta + step_theta, state.offsets_m + step_x)
            # linearised at the trial point at once: an accepted step (most are) needs no second evaluation there
            projected, trial_lin = _evaluate(problem, scale, trial, True, strict=False)
            e_trial = (problem.measured - projected) / problem.sigma_px[:, None]
            trial_cost = _cost(problem, e_trial, trial, use, loss, loss_scale, prior_weight)
            if trial_cost <= cost:
                break
            # the decrease the linearisation predicts for this damped step (Nielsen: d^T (g + damping D d) / 2)
            predicted = 0.5 * (float(step_theta @ (g_theta + damping * np.diag(u) * step_theta))
                               + float(np.sum(step_x * (g_x + damping * np.diagonal(v, axis1=1, axis2=2) * step_x))))
            if rounding and trial_cost - cost <= rounding * cost and predicted <= 1e-6 * cost:
                return state, iteration, True  # a negligible step that only the cost's float64 noise rejects
            damping *= 10.0
            if damping > 1e12:  # no step lowers the cost: at the minimum to rounding
                return state, iteration, True
        decrease = cost - trial_cost
        state = trial
        damping = max(damping / 10.0, 1e-12)
        lin = trial_lin
        assert lin is not None
        cost = trial_cost
        history.append(cost)
        small_step = float(np.max(np.abs(step_theta) * np.sqrt(np.clip(np.diag(u), 0, None))
                                  , initial=0.0)) < 1e-8 and float(np.max(np.abs(step_x), initial=0.0)) < 1e-7
        if decrease <= max(1e-12 * max(cost, 1e-300), cost_tolerance) or small_step:
            return state, iteration, True
    return state, max_iterations, False


def _start(problem: BundleProblem) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray], _State]:
    """Free points (M,), prior weights (M, 3) 1/m^2, metres per degree, and the initial state."""
    free = ~(problem.ground_sigma_m == 0.0).all(axis=1)
    if ((problem.ground_sigma_m == 0.0).any(axis=1) & free).any():
        raise InputError("a ground point's sigmas must be all 0 (fixed) or all > 0")
    prior_weight = np.where(np.isinf(problem.ground_sigma_m), 0.0,
                            1.0 / np.where(free[:, None], problem.ground_sigma_m, 1.0) ** 2)
    prior_weight[~free] = 0.0
    scale = metres_per_degree(problem.ground[:, 1], problem.ground[:, 2], problem.axes)
    state = _State(np.concatenate(problem.initial_parameters), np.zeros((problem.ground.shape[0], 3)))
    return free, prior_weight, scale, state


def bundle_adjust(problem: BundleProblem, *, loss: str = "huber", loss_scale: float = 1.5,
                  outlier_probability: float = 0.999, max_iterations: int = 50,
                  parameter_names: list[str] | None = None) -> BundleResult:
    """Adjust the images' parameters and the free ground points to the observations.

    Parameters
    ----------
    problem : BundleProblem
    loss : {"huber", "cauchy", "linear"}
        Robust loss on each observation's whitened 2-D residual (module docstring).
    loss_scale : float
        Its scale ``c``, in stated sigmas (default 1.5).
    outlier_probability : float
        An observation whose ``s^2`` exceeds the chi-square(2) quantile of this probability after the
        robust solution is an outlier (default 0.999: ``s > 3.72`` sigmas, or that many robust a posteriori
        sigmas when they are larger).
    max_iterations : int
        Of each Levenberg-Marquardt run (robust, then the final least-squares pass).
    parameter_names : list of str, optional
        Names of the stacked parameters, for messages.

    Returns
    -------
    BundleResult

    Raises
    ------
    InputError
        Too few observations (no redundancy), a tie point seen in fewer than two images, a degenerate
        configuration (the points do not determine a parameter), bad sigmas.
    ConvergenceError
        Levenberg-Marquardt did not converge in ``max_iterations``.
    """
    if loss not in LOSSES:
        raise InputError(f"unknown robust loss {loss!r} (one of {', '.join(LOSSES)})")
    if not (math.isfinite(loss_scale) and loss_scale > 0):
        raise InputError(f"loss scale must be a finite number > 0, got {loss_scale}")
    if not 0.0 < outlier_probability < 1.0:
        raise InputError(f"outlier probability must be in (0, 1), got {outlier_probability}")
    offs = problem.offsets
    p_total = int(offs[-1])
    names = parameter_names or [f"p{i}" for i in range(p_total)]
    n = problem.measured.shape[0]
    m = problem.ground.shape[0]
    free, prior_weight, scale, state = _start(problem)

    tie = free & np.isinf(problem.ground_sigma_m).any(axis=1)

    def active_points(use: np.ndarray) -> tuple[np.ndarray, int]:
        """Free points with a prior or seen in an image (the unknowns), and the redundancy."""
        seen = np.bincount(problem.point_index[use], minlength=m)
        active = free & ~(tie & (seen == 0))
        n_priors = int(np.isfinite(problem.ground_sigma_m[active]).sum())
        redundancy = 2 * int(use.sum()) + n_priors - p_total - 3 * int(active.sum())
        if redundancy <= 0:
            raise InputError(f"too few points: {int(use.sum())} observation(s) for {p_total} image parameter(s) "
                             f"and {int(active.sum())} free ground point(s) leave no redundancy")
        return active, redundancy

    seen0 = np.bincount(problem.point_index, minlength=m)
    loose = tie & (seen0 == 1)
    if loose.any():
        raise InputError(f"{int(loose.sum())} tie point(s) measured in fewer than two images "
                         f"(first: point {int(np.flatnonzero(loose)[0])}): their ground is not determined")
    use = np.ones(n, dtype=bool)
    active, _ = active_points(use)
    before, _ = _evaluate(problem, scale, state, False)
    residuals_before = problem.measured - before
    history: list[float] = []
    # the robust pass only has to find the outliers (the estimate is the least-squares pass below): it stops when
    # an iteration lowers the cost by less than ROBUST_COST_TOLERANCE per observation -- reweighting a robust loss
    # converges linearly, crawling over tens of iterations
    state, it1, ok1 = _lm(problem, scale, state, use, active, prior_weight, loss, loss_scale, max_iterations,
                          names, history, ROBUST_COST_TOLERANCE * n if loss != "linear" else 0.0)
    projected, _ = _evaluate(problem, scale, state, False)
    e = (problem.measured - projected) / problem.sigma_px[:, None]
    s2 = (e**2).sum(axis=1)
    # chi-square(2) quantile, in units of the stated sigma or of the robust a posteriori one (the median of
    # s^2 over chi-square(2)'s median 2 ln 2) when that is larger: a model that does not fit flags nothing
    robust_variance = float(np.median(s2)) / (2.0 * math.log(2.0)) if s2.size else 1.0
    threshold = -2.0 * math.log(1.0 - outlier_probability) * max(1.0, robust_variance)
    outlier = s2 > threshold
    # a tie point left in one image by its outliers no longer has a determined ground: drop it whole
    seen = np.bincount(problem.point_index[~outlier], minlength=m)
    outlier |= (tie & (seen < 2))[problem.point_index]
    use = ~outlier
    active, redundancy = active_points(use)
    state.offsets_m[~active] = 0.0
    state, it2, ok2 = _lm(problem, scale, state, use, active, prior_weight, "linear", loss_scale, max_iterations,
                          names, history)
    if not (ok1 and ok2):
        raise ConvergenceError(f"Levenberg-Marquardt did not converge in {max_iterations} iterations")
    _, lin = _evaluate(problem, scale, state, True)
    assert lin is not None
    w = use.astype(np.float64)
    u, g_theta, v, big_g, g_x = _normal_equations(problem, lin, w, state, active, prior_weight)
    s, _, v_inv, t = _reduced_system(u, g_theta, v, big_g, g_x, 0.0)
    d = np.sqrt(np.diag(s))
    s_inv = np.linalg.inv(s / np.outer(d, d)) / np.outer(d, d)
    weighted = float(np.sum(lin.e[use] ** 2) + np.sum(prior_weight * state.offsets_m**2))
    sigma0 = math.sqrt(weighted / redundancy)
    ground_cov = v_inv + np.matmul(t.transpose(0, 2, 1), np.matmul(s_inv, t))
    ground_cov[~active] = 0.0
    return BundleResult(
        parameters=[state.theta[offs[k]:offs[k + 1]].copy() for k in range(len(problem.projectors))],
        parameter_covariance=sigma0**2 * s_inv,
        sigma0=sigma0,
        redundancy=redundancy,
        ground=_ground_geodetic(problem, scale, state.offsets_m),
        ground_covariance_m=sigma0**2 * ground_cov,
        residuals_before=residuals_before,
        residuals_after=problem.measured - projected_after(problem, scale, state),
        outlier=outlier,
        iterations=it1 + it2,
        converged=True,
        cost_history=history,
    )


def projected_after(problem: BundleProblem, scale: tuple[np.ndarray, np.ndarray], state: _State) -> np.ndarray:
    """Projections (N, 2) at ``state``."""
    return _evaluate(problem, scale, state, False)[0]


def lm_iteration(problem: BundleProblem, *, loss: str = "huber", loss_scale: float = 1.5) -> np.ndarray:
    """One Levenberg-Marquardt iteration from the initial values (for benchmarks and teaching).

    Linearises (torch autograd), builds and reduces the normal equations, solves, and evaluates the trial
    step with its linearisation (more damping until the cost drops; the accepted step's linearisation is the
    next iteration's), as every iteration of :func:`bundle_adjust` does (plus its first linearisation).

    Returns
    -------
    ndarray, shape (P,)
        The stacked image parameters after the iteration.
    """
    free, prior_weight, scale, state = _start(problem)
    names = [f"p{i}" for i in range(int(problem.offsets[-1]))]
    use = np.ones(problem.measured.shape[0], dtype=bool)
    state, _, _ = _lm(problem, scale, state, use, free, prior_weight, loss, loss_scale, 1, names, [])
    return state.theta
