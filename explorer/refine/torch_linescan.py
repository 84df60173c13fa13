"""A differentiable (torch, float64, CPU) ground to image of rigorous DIMAP/DG models and USGS CSM cameras with
exterior corrections (:mod:`explorer.refine.line_corrections`).

:class:`TorchRigorous` (a :class:`~explorer.real.linescan.RigorousLineScanScene`: Lagrange ephemeris, Lagrange or
slerp attitude quaternions, sensor-to-body axes, lever arm, aberration of light, refraction, radial distortion,
curved detector line, uneven detector spacing) and :class:`TorchCsm` (a :class:`~explorer.real.csm_sensor.CsmScene`:
usgscsm's Lagrange windows, slerp / Lagrange quaternions, constant and body rotations, J2000 positions,
focal2pixel, summing, every distortion model of :mod:`explorer.real.csm_kernels`) restate the compiled
formulas on torch tensors, with the correction applied to the table samples as
:func:`explorer.refine.line_adjust.adjusted_sensor` applies it.

Ground to image on a line scanner is a search for the line.  The search runs without gradients (the adjusted
sensor's own compiled ground to image); then one Newton step of the line residual is taken in torch from that
root, with the residual's time derivative from autograd, taken as a constant (one forward pass; the column is carried
to the new line by its own autograd derivative).  At the root the step moves the value by less than the compiled
tolerance, and its derivative is the implicit-function derivative ``d line / d theta =
-(d r / d theta) / (d r / d line)``, so ``d (row, col) / d (params)`` and ``d (row, col) / d (ground)`` are exact
(autograd; ``tests/refine/test_torch_linescan.py`` checks them against central differences and against the
closed form of an along-track position offset).  Distortions solved by Newton in the compiled path (usgscsm's
``apply`` of a model stated as a removal) are made differentiable the same way: one Newton step of the closed
form with its autograd Jacobian from the compiled solution.

For an adjustment, ``project_jacobian`` returns the values and the Jacobians by the ground and the parameters in
numpy from one forward pass and two backward passes (the gradients of the line residual and of the across-track
coordinate by time, ground and parameters; the implicit-function derivatives then in closed form), and each
projector remembers its last search: the same parameters and points give the same lines back, and other ones start
from the previous lines (three secant steps of the adjusted sensor's residual, then the compiled bracket about the
result, which checks it; see :meth:`_Projector._roots`).

Points where the compiled path finds no line (behind the sensor, outside the window, outside the ISD's tables)
come out NaN.  Agreement with the compiled path: 1e-10 px on CSM cameras, 1e-9 px on the rigorous models (the
perspective centre interpolated about each window's tangent line, :func:`explorer.real.linescan.lagrange_position_from`,
and the compiled loop's operations in its order; docs/refine.md).  torch is imported by this module only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from explorer.errors import InputError
from explorer.geometry.bracket import bracket_best_scanline
from explorer.refine.line_adjust import adjusted_sensor
from explorer.refine.line_corrections import LineCorrection, quaternion_multiply
from explorer.refine.torch_scene import radially_distorted

__all__ = ["TorchCsm", "TorchRigorous", "line_projector"]


def _t(a: Any) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float64))


def geodetic_to_ecef(lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor, a: float, e2: float) -> torch.Tensor:
    """Body-fixed (N, 3) metres of geodetic degrees, degrees, metres on the ellipsoid (a, e^2)."""
    lam, phi = torch.deg2rad(lon), torch.deg2rad(lat)
    sl, cl = torch.sin(phi), torch.cos(phi)
    n = a / torch.sqrt(1.0 - e2 * sl * sl)
    return torch.stack([(n + h) * cl * torch.cos(lam), (n + h) * cl * torch.sin(lam), (n * (1.0 - e2) + h) * sl],
                       dim=1)


def _weighted_sum(w: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """``sum_j w[:, j] values[:, j]`` (N, K) of weights (N, m) and values (N, m, K), summed in order (as numpy's
    einsum of the compiled path: the same rounding of planetary-size coordinates)."""
    out = w[:, 0, None] * values[:, 0]
    for j in range(1, w.shape[1]):
        out = out + w[:, j, None] * values[:, j]
    return out


def _to_enu(d: torch.Tensor, e: np.ndarray) -> torch.Tensor:
    """ENU (N, 3) of ECEF differences (N, 3) (``e`` columns: ENU axes in ECEF), per component as the frame's."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return torch.stack([float(e[0, k]) * x + float(e[1, k]) * y + float(e[2, k]) * z for k in range(3)], dim=1)


def _quat_matrix(q: torch.Tensor) -> torch.Tensor:
    """(N, 3, 3) active rotation of unit quaternions (N, 4) (w, x, y, z)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    rows = [torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], dim=1),
            torch.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], dim=1),
            torch.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], dim=1)]
    return torch.stack(rows, dim=1)


def _normalise(q: torch.Tensor) -> torch.Tensor:
    return q / torch.sqrt(torch.sum(q * q, dim=-1, keepdim=True))


def _sqrt(x: torch.Tensor) -> torch.Tensor:
    """Square root with the correctly rounded value of the compiled path (numpy's; torch's CPU ``sqrt`` rounds
    ``sqrt(1 - 2^-53)`` up to 1, which turns a rotation matrix by 7e-16) and torch's derivative."""
    root = torch.sqrt(x)
    return torch.from_numpy(np.sqrt(x.detach().numpy())) + (root - root.detach())


def _normalise_ordered(q: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (N, 4), the norm summed in the compiled loop's order."""
    n = _sqrt(q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1] + q[:, 2] * q[:, 2] + q[:, 3] * q[:, 3])
    return q / n[:, None]


def _gradient_only(x: torch.Tensor, like: torch.Tensor | None = None) -> torch.Tensor:
    """Zero with the derivatives of ``x`` (a correction whose value a table already holds); with ``like``, the
    sign of each quaternion (last axis) of ``x`` matched to ``like``'s (a table's sign continuity)."""
    if like is not None:
        x = x * torch.sign(torch.sum(x.detach() * like.detach(), dim=-1, keepdim=True))
    return x - x.detach()


def _base_of(q: torch.Tensor, dq: torch.Tensor) -> torch.Tensor:
    """``q dq^-1`` (N, 4) of unit quaternions (N, 4)."""
    return quaternion_multiply(q, dq * _t([1.0, -1.0, -1.0, -1.0]))


def _rotate(m: torch.Tensor, v: torch.Tensor | np.ndarray) -> torch.Tensor:
    """``m v`` (N, 3) of matrices (3, 3) or (N, 3, 3) and vectors (N, 3) or (3,), per component in order."""
    m = m if m.ndim == 3 else m[None]
    v = v if isinstance(v, torch.Tensor) else _t(v)
    v = v if v.ndim == 2 else v[None]
    return torch.stack([m[:, k, 0] * v[:, 0] + m[:, k, 1] * v[:, 1] + m[:, k, 2] * v[:, 2] for k in range(3)], dim=1)


def _rotate_transposed(m: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``m^T v`` (N, 3) of matrices (3, 3) or (N, 3, 3) and vectors (N, 3), per component in order."""
    m = m if m.ndim == 3 else m[None]
    return torch.stack([m[:, 0, k] * v[:, 0] + m[:, 1, k] * v[:, 1] + m[:, 2, k] * v[:, 2] for k in range(3)], dim=1)


class _Projector:
    """What both projectors share: parameters, the cache of the adjusted compiled sensor, the parameter rows."""

    cost_rounding = 1e-9
    """Relative float64 noise of an adjustment's cost with this projector (its compiled line search defines a
    projection to ~1e-9 px): :data:`explorer.refine.bundle.COST_ROUNDING`."""

    def __init__(self, sensor: Any, correction: LineCorrection) -> None:
        self.sensor = sensor
        self.correction = correction
        self.parameter_names = correction.parameter_names
        self._cache: tuple[bytes, Any] | None = None
        self._last_roots: tuple[bytes, np.ndarray, np.ndarray, np.ndarray] | None = None

    def adjusted(self, params: np.ndarray) -> Any:
        key = np.asarray(params, dtype=np.float64).tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, adjusted_sensor(self.sensor, self.correction, params, reuse_setup=True))
        return self._cache[1]

    def _roots(self, p_np: np.ndarray, points: np.ndarray, solve: Any) -> tuple[np.ndarray, np.ndarray]:
        """The compiled search's (line, column) of ``points`` (N, 3) at parameters ``p_np``: ``solve(points,
        guess)`` with the lines of the previous call on as many points as a warm start (an adjustment's
        iterations move each line by a fraction of a row; the search checks the guess by its bracket and searches
        the whole image where it fails), and the previous answer itself when the parameters and the points are
        the same (a trial step that becomes the next iterate, the final pass of an adjustment)."""
        key = p_np.tobytes()
        last = self._last_roots
        if last is not None and last[1].shape == points.shape:
            if last[0] == key and np.array_equal(last[1], points):
                return last[2], last[3]
            guess = last[2]
        else:
            guess = None
        lines, cols = solve(points, guess)
        self._last_roots = (key, points.copy(), lines, cols)
        return lines, cols

    def forget_roots(self) -> None:
        """Drop the remembered search (a benchmark timing a cold start)."""
        self._last_roots = None

    def _theta(self, params: Any, n: int) -> tuple[torch.Tensor, np.ndarray]:
        theta = params if isinstance(params, torch.Tensor) else _t(params)
        theta = theta.expand(n, -1) if theta.ndim == 1 else theta
        p_np = theta.detach()[0].numpy().copy() if theta.shape[0] else np.zeros(len(self.parameter_names))
        if theta.shape[0] and not torch.equal(theta.detach(), theta.detach()[:1].expand_as(theta)):
            raise InputError("the line-scanner projector takes one set of corrections for all points")
        return theta, p_np

    def _lagrange_weights_compiled_order(self, times: np.ndarray, idx: np.ndarray, t: torch.Tensor) -> torch.Tensor:
        """Lagrange weights (N, m) with the operations of :func:`explorer.real.linescan.lagrange_interpolate` in its
        order (``w_j *= dt_k / (t_j - t_k)``): the ephemeris' positions (7e6 m) round as the compiled path's."""
        tw = times[idx]
        dt = t[:, None] - _t(tw)
        m = idx.shape[1]
        cols = []
        for j in range(m):
            w = torch.ones_like(t)
            for k in range(m):
                if k != j:
                    w = w * (dt[:, k] / _t(tw[:, j] - tw[:, k]))
            cols.append(w)
        return torch.stack(cols, dim=1)

    def _lagrange_weights(self, times: np.ndarray, idx: np.ndarray, t: torch.Tensor) -> torch.Tensor:
        """Lagrange weights (N, m) of samples ``times[idx]`` (N, m) at ``t`` (N,)."""
        tw = times[idx]
        m = idx.shape[1]
        den = np.ones(tw.shape)
        for j in range(m):
            for k in range(m):
                if k != j:
                    den[:, j] *= tw[:, j] - tw[:, k]
        return _weights(t[:, None] - _t(tw), _t(1.0 / den))


def _weights(dt: torch.Tensor, inv_den: torch.Tensor) -> torch.Tensor:
    """Lagrange weights ``inv_den[:, a] prod_{b != a} dt[:, b]`` (N, m) by prefix and suffix products (2m products
    instead of m^2)."""
    m = dt.shape[1]
    if m == 1:
        return inv_den
    prefix = [torch.ones_like(dt[:, 0])]
    for b in range(m - 1):
        prefix.append(prefix[-1] * dt[:, b])
    suffix = [torch.ones_like(dt[:, 0])]
    for b in range(m - 1, 0, -1):
        suffix.append(suffix[-1] * dt[:, b])
    return torch.stack([prefix[a] * suffix[m - 1 - a] for a in range(m)], dim=1) * inv_den


def _constant_attitude(correction: LineCorrection) -> bool:
    """True when the attitude correction does not vary along the line time (no drifts, no harmonics): it then
    commutes with the tables' interpolation (Lagrange is linear, slerp isometric) and is applied once per point."""
    return not any(n.endswith("rad_per_s") for n in correction.parameter_names) and not correction.frequencies_hz


class TorchRigorous(_Projector):
    """Ground (lon, lat, h on the frame's body) -> corrected (row, col) of a rigorous DIMAP/DG model.

    Parameters
    ----------
    scene : RigorousLineScanScene
    correction : LineCorrection
    """

    def __init__(self, scene: Any, correction: LineCorrection) -> None:
        super().__init__(scene, correction)
        ext = scene.exterior
        self._e = np.asarray(scene.frame.enu_to_ecef_rotation, dtype=np.float64)
        self._origin = np.asarray(scene.frame.origin_ecef, dtype=np.float64)
        self._b = np.asarray(ext.sensor_to_body, dtype=np.float64)
        self._lever = np.asarray(ext.centre_offset_body_m, dtype=np.float64)
        self.line_period = float(scene.timing.line_period_s)
        eph, att = ext.ephemeris, ext.attitude
        correction.check_sampling(att.time_s, "sensor's")
        self._eph = eph
        self._att = att

    # ------------------------------------------------------------ exterior
    def _window(self, times: np.ndarray, t: np.ndarray, order: int) -> np.ndarray:
        n = times.size
        m = min(order, n)
        start = np.clip(np.searchsorted(times, t) - m // 2, 0, n - m)
        return start[:, None] + np.arange(m)[None, :]

    def exterior(self, t: torch.Tensor, theta: torch.Tensor) -> tuple[tuple[torch.Tensor, torch.Tensor], torch.Tensor,
                                                                     torch.Tensor]:
        """Perspective centres (N, 3) ENU as (fixed, moving) parts (``centre = fixed + moving``,
        :meth:`explorer.real.linescan.LineScanExterior.position_parts`), body -> ECEF rotations (N, 3, 3), velocities
        (N, 3) ENU at times ``t`` (N,) with corrections ``theta`` (N, P) (the sensor -> ENU rotation is ``E^T Q S``,
        ``S`` the sensor to body axes)."""
        corr = self.correction
        t_ref = corr.reference_time_s
        att = self._att
        # the values of the adjusted sensor's own (corrected, rounded) tables, as the compiled path reads them; the
        # derivatives by the parameters from the correction below
        adjusted = self.adjusted(theta.detach()[0].numpy() if theta.shape[0] else
                                 np.zeros(len(self.parameter_names)))
        eph = adjusted.exterior.ephemeris
        t_np = t.detach().numpy()
        idx = self._window(eph.time_s, t_np, eph.order)
        w = self._lagrange_weights_compiled_order(eph.time_s, idx, t)
        # position minus the frame's origin about the tangent line of the window's middle sample, in the order of
        # linescan.lagrange_position_from and the compiled loop (no round-off of 7,000 km coordinates)
        mid = idx[:, idx.shape[1] // 2]
        t_r, p_r, v_r = eph.time_s[mid], eph.position_m[mid], eph.velocity_m_s[mid]
        departure = (eph.position_m[idx] - p_r[:, None, :]) - v_r[:, None, :] * (eph.time_s[idx] - t_r[:, None])[
            :, :, None]
        fixed = _t(p_r - self._origin)
        pos = _t(v_r) * (t - _t(t_r))[:, None] + _weighted_sum(w, _t(departure))  # the motion from the fixed part
        vel = _weighted_sum(w, _t(eph.velocity_m_s[idx]))
        if corr.has_position:
            tau = torch.sum(w.detach() * _t(eph.time_s[idx] - t_ref), dim=1)
            off = corr.position_offset(tau, theta)
            vel_off = corr.position_offset(tau + 1.0, theta) - off
            pos = pos + _gradient_only(off)  # the value is in the table already
            vel = vel + _gradient_only(vel_off)
        # attitude: the values of the adjusted sensor's (corrected, normalised) quaternion table, interpolated in
        # the compiled loop's order; the derivatives by the parameters from the corrected base samples (q_i dq(t_i);
        # a constant dq applied once per point after the interpolation)
        adj = adjusted.exterior.attitude
        constant = _constant_attitude(corr)
        if att.method == "lagrange":
            aidx = self._window(att.time_s, t_np, att.order)
            q = _t(adj.quaternion[aidx])
            if not constant:
                q = q + _gradient_only(self._corrected_quaternions(aidx, theta), q)
            wa = self._lagrange_weights_compiled_order(att.time_s, aidx, t)
            qt = _normalise_ordered(_normalise_ordered(_weighted_sum(wa, q)))  # quaternion_to_matrix normalises again
        else:
            i = np.clip(np.searchsorted(att.time_s, t_np) - 1, 0, att.time_s.size - 2)
            pair = np.stack([i, i + 1], axis=1)
            q = _t(adj.quaternion[pair])
            if not constant:
                q = q + _gradient_only(self._corrected_quaternions(pair, theta), q)
            s = (t - _t(att.time_s[i])) / _t(att.time_s[i + 1] - att.time_s[i])
            qt = _normalise_ordered(_slerp(q[:, 0], q[:, 1], s, flip=True, normalise=False))
        if constant and corr.n_parameters:
            dq = corr.rotation_quaternion(torch.zeros_like(t), theta, self._b)
            qt = qt + _gradient_only(_normalise(quaternion_multiply(_base_of(qt.detach(), dq.detach()), dq)), qt)
        rot_body = _quat_matrix(qt)  # body -> ECEF
        if np.any(self._lever):
            pos = pos + _rotate(rot_body, self._lever)
        return (_to_enu(fixed, self._e), _to_enu(pos, self._e)), rot_body, _to_enu(vel, self._e)

    def _corrected_quaternions(self, idx: np.ndarray, theta: torch.Tensor) -> torch.Tensor:
        corr = self.correction
        tau = _t(self._att.time_s[idx] - corr.reference_time_s)  # (N, m)
        dq = corr.rotation_quaternion(tau, theta[:, None, :], self._b)
        base = _t(self._att.quaternion[idx])
        return _normalise(quaternion_multiply(base, dq))

    # ------------------------------------------------------------ collinearity
    def focal_plane(self, ground: torch.Tensor, geodetic: tuple[torch.Tensor, ...], t: torch.Tensor,
                    theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Distorted focal-plane (x, y) (N,) metres of ENU ``ground`` (N, 3) at times ``t`` (N,)."""
        scene = self.sensor
        (fixed, moving), rot_body, velocity = self.exterior(t, theta)
        centre = fixed + moving
        target = ground
        if scene.refraction:
            target = ground + self._refraction_shift(ground, geodetic, centre)
        d = (target - fixed) - moving
        if scene.aberration:
            from explorer.real.linescan import C_LIGHT, OMEGA_EARTH

            omega = _t(OMEGA_EARTH * self._e[2]).expand_as(centre)
            rel = velocity + torch.linalg.cross(omega, centre - ground, dim=1)
            rho = _sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
            d = d / rho[:, None] + rel / C_LIGHT
        # v = S^T Q^T E d, one factor at a time in the compiled loop's order
        v = _rotate_transposed(_t(self._b), _rotate_transposed(rot_body, _rotate(_t(self._e), d)))
        interior = scene.interior
        scale = -interior.focal_length_m / v[:, 2]
        x, y = v[:, 0] * scale, v[:, 1] * scale
        return radially_distorted(x, y, interior.radial_distortion)

    def _refraction_shift(self, ground: torch.Tensor, geodetic: tuple[torch.Tensor, ...],
                          centre: torch.Tensor) -> torch.Tensor:
        from explorer.real.linescan import REFRACTIVITY_SEA_LEVEL, SCALE_HEIGHT_M

        lon, lat, h = geodetic
        lo, la = torch.deg2rad(lon), torch.deg2rad(lat)
        up = torch.stack([torch.cos(la) * torch.cos(lo), torch.cos(la) * torch.sin(lo), torch.sin(la)], dim=1)
        up = up @ _t(self._e)
        los = centre - ground
        los = los / torch.linalg.norm(los, dim=1, keepdim=True)
        cz = torch.clamp(torch.sum(los * up, dim=1), 1e-6, 1.0)
        tz = torch.sqrt(1.0 - cz * cz) / cz
        shift = REFRACTIVITY_SEA_LEVEL * SCALE_HEIGHT_M * torch.exp(-torch.clamp(h, min=-500.0) / SCALE_HEIGHT_M) \
            * tz / cz**2
        away = -(los - cz[:, None] * up)
        norm = torch.linalg.norm(away, dim=1, keepdim=True)
        away = torch.where(norm > 0, away / torch.where(norm > 0, norm, torch.ones_like(norm)), torch.zeros_like(away))
        return shift[:, None] * away

    def _detector_x(self, y: torch.Tensor) -> torch.Tensor:
        interior = self.sensor.interior
        x = torch.full_like(y, interior.along_track_offset_m)
        power = torch.ones_like(y)
        for c in interior.line_curvature:
            power = power * y
            x = x + c * power
        return x

    # ------------------------------------------------------------ ground to image
    def project(self, lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor,
                params: torch.Tensor | Any) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col), each (N,), of geodetic ground points (N,) on the frame's body; ``params`` (P,) or
        (N, P) (equal rows)."""
        frame = self.sensor.frame
        ecef = geodetic_to_ecef(lon, lat, h, float(frame.body.a_m), float(frame.body.e2))
        return self.project_enu(_to_enu(ecef - _t(self._origin), self._e), params, (lon, lat, h))

    def project_enu(self, ground: torch.Tensor, params: torch.Tensor | Any,
                    geodetic: tuple[torch.Tensor, ...] | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col) of local ENU points (N, 3) of the scene's frame (``geodetic``: the same points'
        lon, lat, h tensors for the refraction; default from the frame, without gradients).

        (The geodetic -> ENU conversion of :meth:`project` goes through body-fixed coordinates of planetary
        size, rounded to about 1e-9 m; this entry point avoids it.)
        """
        if geodetic is None:
            geodetic = tuple(_t(v) for v in self.sensor.frame.enu_to_geodetic(ground.detach().numpy()))
        theta, p_np = self._theta(params, ground.shape[0])
        row0, col0 = self._search(p_np, ground.detach().numpy())
        t0 = _t(self.sensor.scanline_time(row0)).requires_grad_(True)
        keep = torch.is_grad_enabled()
        with torch.enable_grad():  # d r / d t and d y / d t by autograd, also when the caller needs no gradients
            x, y = self.focal_plane(ground, geodetic, t0, theta)
            residual = x - self._detector_x(y)
            (slope,) = torch.autograd.grad(residual.sum(), t0, retain_graph=True)
            (y_rate,) = torch.autograd.grad(y.sum(), t0, retain_graph=keep)
        # the Newton step (slopes as constants: at the root the implicit-function derivative is exact), and y
        # carried to the new time to first order (the step is below the compiled tolerance)
        dt = -residual / slope
        row = _t(row0) + dt / self.line_period
        return row, self._column(y + y_rate * dt, col0)[0]

    def _search(self, p_np: np.ndarray, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        scene = self._cache_scene(p_np)

        def solve(points: np.ndarray, guess: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
            if guess is None:
                return scene.ground_to_image(points)
            # three secant steps of this sensor's residual from the previous lines (four evaluations; each step
            # divides the error by ~1e4 after an iteration's step of a hundred rows), then the compiled bracket
            # (the model's own root to 1e-10 rows, as without a guess) about the result, four times the last step
            # + 3e-9 rows wide (above the residual's float64 wobble): a point whose residual does not change sign
            # there is searched over the whole image
            r0 = scene.along_track_residual(points, scene.scanline_time(guess))
            r1 = scene.along_track_residual(points, scene.scanline_time(guess + 1.0))
            with np.errstate(divide="ignore", invalid="ignore"):
                slope = r1 - r0
                step = r0 / slope
                for _ in range(2):
                    guess = guess - step
                    step = scene.along_track_residual(points, scene.scanline_time(guess)) / slope
                guess = guess - step
            row, col, _ = bracket_best_scanline(scene, points, row_guess=guess,
                                                guess_halfwidth_rows=4.0 * np.abs(step) + 3e-9)
            return row, col

        return self._roots(p_np, ground, solve)

    def _column(self, y: Any, col0: np.ndarray) -> tuple[Any, Any]:
        """Column (N,) of the focal-plane ``y`` (N,) near the compiled column ``col0`` (one Newton step of the
        uneven detector spacing from it) and ``d column / d y`` (N,), tensors or arrays."""
        interior = self.sensor.interior
        target = y / interior.detector_pitch_m
        if not interior.column_polynomial:
            return target + interior.principal_column, 1.0 / interior.detector_pitch_m
        u = col0 - interior.principal_column
        if isinstance(y, torch.Tensor):
            u = _t(u)
        g = u * 1.0
        dg = u * 0.0 + 1.0
        power = u * 1.0
        for k, a in enumerate(interior.column_polynomial, start=2):
            dg = dg + k * a * power
            power = power * u
            g = g + a * power
        return u - (g - target) / dg + interior.principal_column, 1.0 / (interior.detector_pitch_m * dg)

    def project_jacobian(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray,
                         params: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`project` of geodetic points (N,) with its Jacobians, from one forward pass and two backward passes.

        The implicit-function derivatives of :meth:`project` (its Newton step with the slopes as constants)
        formed in closed form from the gradients of the line residual ``r`` and the across-track ``y`` by the
        scanline time, the ground and the parameters: ``d row = -d r / (r_t T)``, ``d y' = d y - y_t d r / r_t``.

        Returns
        -------
        row, col : ndarray, shape (N,)
        j_ground : ndarray, shape (N, 2, 3)
            d (row, col) / d (lon deg, lat deg, h m).
        j_params : ndarray, shape (N, 2, P)
        """
        frame = self.sensor.frame
        n = np.asarray(lon).shape[0]
        geo = [_t(v).requires_grad_(True) for v in (lon, lat, h)]
        theta = _t(np.broadcast_to(np.asarray(params, dtype=np.float64), (n, len(self.parameter_names))).copy())
        theta.requires_grad_(True)
        p_np = np.asarray(params, dtype=np.float64).reshape(-1, len(self.parameter_names))[0].copy() \
            if n else np.zeros(len(self.parameter_names))
        with torch.enable_grad():
            ecef = geodetic_to_ecef(geo[0], geo[1], geo[2], float(frame.body.a_m), float(frame.body.e2))
            ground = _to_enu(ecef - _t(self._origin), self._e)
            row0, col0 = self._search(p_np, ground.detach().numpy())
            t0 = _t(self.sensor.scanline_time(row0)).requires_grad_(True)
            x, y = self.focal_plane(ground, tuple(geo), t0, theta)
            residual = x - self._detector_x(y)
            leaves = (t0, *geo, theta)
            g_r = torch.autograd.grad(residual.sum(), leaves, retain_graph=True, allow_unused=True)
            g_y = torch.autograd.grad(y.sum(), leaves, allow_unused=True)
        return _implicit(row0, col0, residual, y, g_r, g_y, n, self.line_period, self._column)

    def _cache_scene(self, p_np: np.ndarray) -> Any:
        return self.adjusted(p_np)


def _stack_gradients(g: tuple[torch.Tensor | None, ...], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d/d line-or-time (N,), d/d ground (N, 3), d/d params (N, P)) of autograd's gradients (None: zero)."""
    def arr(v: torch.Tensor | None, shape: tuple[int, ...]) -> np.ndarray:
        return np.zeros(shape) if v is None else v.numpy()

    p = g[4].shape[1] if g[4] is not None else 0
    ground = np.stack([arr(v, (n,)) for v in g[1:4]], axis=1)
    return arr(g[0], (n,)), ground, arr(g[4], (n, p))


def _implicit(line0: np.ndarray, col0: np.ndarray, residual: torch.Tensor, across: torch.Tensor,
              g_r: tuple[torch.Tensor | None, ...], g_a: tuple[torch.Tensor | None, ...], n: int, line_scale: float,
              column: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The Newton step of the line residual from the compiled root and its implicit-function Jacobians, in numpy
    (the same operations as the projectors' torch path): ``step = -r / r_t``, ``line = line0 + step / line_scale``,
    ``across' = across + a_t step``, ``column = column(across')``."""
    r_t, r_g, r_p = _stack_gradients(g_r, n)
    a_t, a_g, a_p = _stack_gradients(g_a, n)
    r = residual.detach().numpy()
    a = across.detach().numpy()
    step = -r / r_t
    row = line0 + step / line_scale
    col, dcol = column(a + a_t * step, col0)
    dstep_g, dstep_p = -r_g / r_t[:, None], -r_p / r_t[:, None]
    dcol = np.broadcast_to(np.asarray(dcol, dtype=np.float64), (n,))[:, None]
    j_ground = np.stack([dstep_g / line_scale, dcol * (a_g + a_t[:, None] * dstep_g)], axis=1)
    j_params = np.stack([dstep_p / line_scale, dcol * (a_p + a_t[:, None] * dstep_p)], axis=1)
    return row, col, j_ground, j_params


    def _cache_scene(self, p_np: np.ndarray) -> Any:
        return self.adjusted(p_np)


def _slerp(q0: torch.Tensor, q1: torch.Tensor, s: torch.Tensor, flip: bool, normalise: bool = True) -> torch.Tensor:
    """Slerp (N, 4) between unit quaternions (N, 4) at fractions (N,): ``flip`` as
    :func:`explorer.real.linescan.slerp` (the shorter arc), else as the CSM kernel (dot clipped at 1)."""
    dot = torch.sum(q0 * q1, dim=1)
    if flip:
        q1 = torch.where((dot < 0)[:, None], -q1, q1)
        dot = torch.abs(dot)
        theta = torch.arccos(torch.clamp(dot, -1.0, 1.0))
    else:
        theta = torch.arccos(torch.clamp(dot, max=1.0))
    st = torch.sin(theta)
    small = st < 1e-12
    safe = torch.where(small, torch.ones_like(st), st)
    w0 = torch.where(small, 1.0 - s, torch.sin((1.0 - s) * theta) / safe)
    w1 = torch.where(small, s, torch.sin(s * theta) / safe)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return _normalise(q) if normalise else q


# ------------------------------------------------------------------------------------------- CSM
def _closed_form(model: int, c: np.ndarray, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`explorer.real.csm_kernels._closed_form` on tensors."""
    from explorer.real import csm_kernels as K

    c = [float(v) for v in c]  # type: ignore[assignment]
    if model == K.DIST_RADIAL:
        rr = x * x + y * y
        dr = c[0] + rr * (c[1] + rr * c[2])
        return x * (1.0 - dr), y * (1.0 - dr)
    if model == K.DIST_TRANSVERSE:
        f = (x, y, x * x, x * y, y * y, x * x * x, x * x * y, x * y * y, y * y * y)
        ox = c[0] + sum(c[1 + k] * f[k] for k in range(9))
        oy = c[10] + sum(c[11 + k] * f[k] for k in range(9))
        return ox, oy
    if model == K.DIST_KAGUYALISM:
        r2 = x * x + y * y
        r = torch.sqrt(r2)
        r3 = r2 * r
        return (x + (c[1] + c[2] * r + c[3] * r2 + c[4] * r3) + c[0],
                y + (c[6] + c[7] * r + c[8] * r2 + c[9] * r3) + c[5])
    if model == K.DIST_DAWNFC:
        r2 = x * x + y * y
        return x * (1.0 + c[0] * r2), y * (1.0 + c[0] * r2)
    if model == K.DIST_LROLROCNAC:
        return x, y / (1.0 + c[0] * y * y)
    if model == K.DIST_CAHVOR:
        sx, sy = x - c[3], y - c[4]
        rr = sx * sx + sy * sy
        dr = c[0] + rr * (c[1] + rr * c[2])
        return sx * (1.0 - dr) + c[3], sy * (1.0 - dr) + c[4]
    if model == K.DIST_LUNARORBITER:
        pf = 1.0 + c[0] * x + c[1] * y
        pcx, pcy = x * pf, y * pf
        sx, sy = pcx - c[2], pcy - c[3]
        dr = c[4] + c[5] * (sx * sx + sy * sy)
        return pcx - dr * sx, pcy - dr * sy
    if model == K.DIST_RADTAN:
        f = c[5]
        u, v = x / f, y / f
        rr = u * u + v * v
        radial = 1.0 + rr * (c[0] + rr * (c[1] + rr * c[4]))
        du = u * radial + 2.0 * c[2] * u * v + c[3] * (rr + 2.0 * u * u)
        dv = v * radial + c[2] * (rr + 2.0 * v * v) + 2.0 * c[3] * u * v
        return du * f, dv * f
    if model == K.DIST_KPLOSHADOWCAM:
        return x, y * (1.0 + c[0] * y * y)
    if model == K.DIST_LEGENDRE:
        half = c[0]
        s = -x / half
        s2 = s * s
        p1, p2 = s, 0.5 * (3.0 * s2 - 1.0)
        p3 = 0.5 * s * (5.0 * s2 - 3.0)
        p4 = (35.0 * s2 * s2 - 30.0 * s2 + 3.0) / 8.0
        p5 = s * (63.0 * s2 * s2 - 70.0 * s2 + 15.0) / 8.0
        q2, q4 = -0.5, 0.375
        d = c[2] * p1 + c[3] * q2 + c[5] * p2 + c[7] * p1 * q2 + c[9] * p3 + c[10] * q4 + c[12] * p2 * q2 \
            + c[14] * p4 + c[16] * p1 * q4 + c[18] * p3 * q2 + c[20] * p5
        return -(s + d) * half, y
    if model == K.DIST_THEMISIR:
        rad = (1.0 + c[1]) * (1.0 + c[1]) + 4.0 * c[2] * y
        ok = rad >= 0
        root = torch.sqrt(torch.where(ok, rad, torch.ones_like(rad)))
        nan = torch.full_like(y, math.nan)
        return torch.where(ok, x / c[0], nan), torch.where(ok, 2.0 * y / (1.0 + c[1] + root), nan)
    return x, y


class TorchCsm(_Projector):
    """Ground (lon, lat, h on the ISD's ellipsoid) -> corrected (row, col) of a USGS CSM camera
    (``(row, col) = (line - 0.5, sample - 0.5)``, ``docs/conventions.md``).

    Parameters
    ----------
    scene : CsmScene
    correction : LineCorrection
    """

    def __init__(self, scene: Any, correction: LineCorrection) -> None:
        super().__init__(scene, correction)
        cam = scene.camera
        self.camera = cam
        correction.check_sampling(cam.pointing_times, "ISD's pointing")
        (self._pos_t, self._pos, self._pos_ref, self._pw, self._pd, self._qp_t, self._qp, self._qpw, self._qpd,
         self._cp, self._qb_t, self._qb, self._qbw, self._qbd, self._cb, self._mode, self._rotate,
         self._simple) = cam._exterior_args()
        self._cam = np.asarray(cam._cam, dtype=np.float64)
        self._look_axes = np.asarray(cam.pointing_constant, dtype=np.float64).T

    def _lagrange(self, times: np.ndarray, win: np.ndarray, den: np.ndarray, t: torch.Tensor,
                  values: Any) -> torch.Tensor:
        """usgscsm's windowed Lagrange of ``values(idx)`` -> (N, m, k) at ``t`` (N,): (N, k)."""
        n = times.size
        if n == 1:
            return values(np.zeros((t.shape[0], 1), dtype=np.int64))[:, 0]
        t_np = t.detach().numpy()
        i = np.clip(np.searchsorted(times, t_np, side="right") - 1, 0, n - 2)
        i = np.where(np.isfinite(t_np), i, 0)
        first, order = self._win(win, i)
        out = None
        for m in np.unique(order):
            sel = np.flatnonzero(order == m)
            idx = first[sel, None] + np.arange(m)[None, :]
            w = _weights(t[sel][:, None] - _t(times[idx]), _t(den[i[sel], :m]))
            part = _weighted_sum(w, values(idx, sel))
            if out is None:
                out = torch.zeros((t.shape[0], part.shape[1]), dtype=torch.float64)
            out = out.index_put((torch.from_numpy(sel),), part)
        assert out is not None
        return out

    @staticmethod
    def _win(win: np.ndarray, i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return win[i, 0], win[i, 1]

    def _quaternion(self, times: np.ndarray, quats: np.ndarray, win: np.ndarray, den: np.ndarray, t: torch.Tensor,
                    correct: torch.Tensor | None) -> torch.Tensor:
        """Interpolated unit quaternions (N, 4); ``correct`` (N, P) corrects the samples (pointing only)."""
        corr = self.correction

        def samples(idx: np.ndarray, sel: np.ndarray | None = None) -> torch.Tensor:
            q = _t(quats[idx])
            if correct is None:
                return q
            th = correct if sel is None else correct[torch.from_numpy(sel)]
            tau = _t(times[idx] - corr.reference_time_s)
            dq = corr.rotation_quaternion(tau, th[:, None, :], self._look_axes, inverse=True)
            return _normalise(quaternion_multiply(dq, q))

        if times.size == 1:
            return _normalise(samples(np.zeros((t.shape[0], 1), dtype=np.int64))[:, 0])
        if self._mode == 1:
            return _normalise(self._lagrange(times, win, den, t, samples))
        t_np = t.detach().numpy()
        i = np.clip(np.searchsorted(times, t_np, side="right") - 1, 0, times.size - 2)
        i = np.where(np.isfinite(t_np), i, 0)
        q = samples(np.stack([i, i + 1], axis=1))
        s = (t - _t(times[i])) / _t(times[i + 1] - times[i])
        return _slerp(q[:, 0], q[:, 1], s, flip=False)

    def exterior(self, t: torch.Tensor, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Perspective centres (N, 3) body-fixed and camera -> body rotations (N, 3, 3) at camera times (N,)."""
        corr = self.correction
        pos_t = self._pos_t

        table = np.concatenate([self._pos, (pos_t - corr.reference_time_s)[:, None]], axis=1)

        def positions(idx: np.ndarray, sel: np.ndarray | None = None) -> torch.Tensor:
            return _t(table[idx])

        pt = self._lagrange(pos_t, self._pw, self._pd, t, positions)  # positions and tau = t_i - t_ref together
        p = pt[:, :3] + _t(self._pos_ref)
        if corr.has_position:
            p = p + corr.position_offset(pt[:, 3], theta)
        constant = _constant_attitude(corr)
        qp = self._quaternion(self._qp_t, self._qp, self._qpw, self._qpd, t, None if constant else theta)
        if constant:
            dq = corr.rotation_quaternion(torch.zeros_like(t), theta, self._look_axes, inverse=True)
            qp = _normalise(quaternion_multiply(dq, qp))
        if self._simple:
            return p, _quat_matrix(qp).transpose(1, 2)
        pm = _t(self._cp) @ _quat_matrix(qp)
        qb = self._quaternion(self._qb_t, self._qb, self._qbw, self._qbd, t, None)
        b = _t(self._cb) @ _quat_matrix(qb)
        m = b @ pm.transpose(1, 2)
        if self._rotate:
            p = torch.einsum("nij,nj->ni", b, p)
        return p, m

    def _line_time(self, line: torch.Tensor) -> torch.Tensor:
        cam = self.camera
        k = np.clip(np.searchsorted(cam.rate_lines, line.detach().numpy(), side="right") - 1, 0, None)
        return _t(cam.rate_times[k]) + _t(cam.rate_periods[k]) * (line - _t(cam.rate_lines[k]) + 0.5)

    def _distort(self, xu: torch.Tensor, yu: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """usgscsm's apply_distortion on tensors (implicit Newton step where the compiled path solves it)."""
        from explorer.real import csm_kernels as K

        cam = self.camera
        model, c = int(cam.distortion_model), np.asarray(cam.distortion_coefficients, dtype=np.float64)
        if model == K.DIST_NONE:
            return xu, yu
        if not bool(K.closed_form_is_removal(model)):
            return _closed_form(model, c, xu, yu)
        xd0, yd0 = cam.apply_distortion(xu.detach().numpy(), yu.detach().numpy())
        a = _t(xd0).requires_grad_(True)
        b = _t(yd0).requires_grad_(True)
        with torch.enable_grad():
            fx, fy = _closed_form(model, c, a, b)
            jxx, jxy = torch.autograd.grad(fx.sum(), (a, b), retain_graph=True)
            jyx, jyy = torch.autograd.grad(fy.sum(), (a, b))
        ex, ey = fx.detach() - xu, fy.detach() - yu
        det = jxx * jyy - jxy * jyx
        return _t(xd0) - (jyy * ex - jxy * ey) / det, _t(yd0) - (jxx * ey - jyx * ex) / det

    def residual(self, xyz: torch.Tensor, line: torch.Tensor, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """usgscsm's detector-line residual (lines) and sample of body-fixed ``xyz`` (N, 3) at ``line`` (N,)."""
        from explorer.real import csm_kernels as K

        cam = self._cam
        s, m = self.exterior(self._line_time(line), theta)
        d = cam[K.C_LOOK] * (xyz - s)
        v = torch.einsum("nji,nj->ni", m, d)
        f = cam[K.C_FOCAL]
        xd, yd = self._distort(f * v[:, 0] / v[:, 2], f * v[:, 1] / v[:, 2])
        det_line = cam[K.C_TL0] + cam[K.C_TL1] * xd + cam[K.C_TL2] * yd + cam[K.C_LINE_ORIGIN] - cam[K.C_START_LINE]
        det_sample = (cam[K.C_TS0] + cam[K.C_TS1] * xd + cam[K.C_TS2] * yd + cam[K.C_SAMPLE_ORIGIN]
                      - cam[K.C_START_SAMPLE])
        return det_line / cam[K.C_LINE_SUM], det_sample / cam[K.C_SAMPLE_SUM]

    def project(self, lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor,
                params: torch.Tensor | Any) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col), each (N,), of geodetic ground points (N,) on the ISD's ellipsoid; ``params`` (P,)
        or (N, P) (equal rows)."""
        cam = self.camera
        a, b = float(cam.semi_major_m), float(cam.semi_minor_m)
        xyz = geodetic_to_ecef(lon, lat, h, a, 1.0 - (b * b) / (a * a))
        return self.project_xyz(xyz, params)

    def project_xyz(self, xyz: torch.Tensor, params: torch.Tensor | Any) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col) of body-fixed points (N, 3), metres."""
        theta, p_np = self._theta(params, xyz.shape[0])
        line0 = _t(self._search(p_np, xyz.detach().numpy())).requires_grad_(True)
        keep = torch.is_grad_enabled()
        with torch.enable_grad():
            res, sample = self.residual(xyz, line0, theta)
            (slope,) = torch.autograd.grad(res.sum(), line0, retain_graph=True)
            (sample_rate,) = torch.autograd.grad(sample.sum(), line0, retain_graph=keep)
        step = -res / slope  # the Newton step with the slopes as constants (exact implicit derivatives at the root)
        return line0.detach() + step - 0.5, sample + sample_rate * step - 0.5

    def _search(self, p_np: np.ndarray, xyz: np.ndarray) -> np.ndarray:
        """The adjusted camera's compiled lines (N,) of body-fixed points (NaN where it finds none)."""
        camera = self.adjusted(p_np).camera

        def solve(points: np.ndarray, guess: Any) -> tuple[np.ndarray, np.ndarray]:
            g = camera.ground_to_image(points)
            return np.where(g.status == 0, g.line, np.nan), np.empty(0)

        return self._roots(p_np, xyz, solve)[0]

    def project_jacobian(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray,
                         params: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`project` of geodetic points (N,) with its Jacobians (as :meth:`TorchRigorous.project_jacobian`:
        one forward and two backward passes, the implicit-function derivatives in closed form).

        Returns
        -------
        row, col : ndarray, shape (N,)
        j_ground : ndarray, shape (N, 2, 3)
            d (row, col) / d (lon deg, lat deg, h m).
        j_params : ndarray, shape (N, 2, P)
        """
        cam = self.camera
        n = np.asarray(lon).shape[0]
        a, b = float(cam.semi_major_m), float(cam.semi_minor_m)
        geo = [_t(v).requires_grad_(True) for v in (lon, lat, h)]
        theta = _t(np.broadcast_to(np.asarray(params, dtype=np.float64), (n, len(self.parameter_names))).copy())
        theta.requires_grad_(True)
        p_np = np.asarray(params, dtype=np.float64).reshape(-1, len(self.parameter_names))[0].copy() \
            if n else np.zeros(len(self.parameter_names))
        with torch.enable_grad():
            xyz = geodetic_to_ecef(geo[0], geo[1], geo[2], a, 1.0 - (b * b) / (a * a))
            line0 = _t(self._search(p_np, xyz.detach().numpy())).requires_grad_(True)
            res, sample = self.residual(xyz, line0, theta)
            leaves = (line0, *geo, theta)
            g_r = torch.autograd.grad(res.sum(), leaves, retain_graph=True, allow_unused=True)
            g_s = torch.autograd.grad(sample.sum(), leaves, allow_unused=True)
        row, col, j_ground, j_params = _implicit(line0.detach().numpy(), np.empty(0), res, sample, g_r, g_s, n, 1.0,
                                                 lambda s_, _c: (s_ - 0.5, 1.0))
        return row - 0.5, col, j_ground, j_params


def line_projector(sensor: Any, correction: LineCorrection) -> TorchRigorous | TorchCsm:
    """The differentiable projector of a rigorous DIMAP/DG model or a CSM camera."""
    from explorer.real.csm_sensor import CsmScene

    if isinstance(sensor, CsmScene):
        return TorchCsm(sensor, correction)
    return TorchRigorous(sensor, correction)
