"""A differentiable (torch, float64, CPU) ground to image of an MPC scene with exterior corrections.

The scene (:class:`explorer.scene.Scene`: MPC polynomials of time, jitter, radial distortion, a curved
detector line, uneven detector spacing; ``docs/conventions.md``) is adjusted by corrections of its
polynomial coefficients (:data:`SCENE_MODELS`):

- ``attitude``: offsets of the perspective centre (east, north, up, metres) and of the angles
  (omega, phi, kappa, radians) -- the degree-0 coefficients;
- ``attitude-drift``: the same plus their drifts along the line time (m/s, rad/s) -- the degree-1
  coefficients.

Ground to image: the compiled path of the adjusted scene (:meth:`Scene.ground_to_image`, the bracketed
best scanline) gives the row; torch then takes one Newton step of the along-track residual from it
(with autograd's ``dr/dt``) and one of the column from the across-track coordinate.  At the root the
step changes the value by less than the compiled tolerance, and its derivative is the implicit-function
derivative ``d row / d theta = -(dr/d theta) / (dr/dt)``: the gradients with respect to the ground point and
the corrections are exact (autograd, no finite differences), the values equal the compiled path within
1e-9 px (``tests/refine/test_torch_scene.py``).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from explorer.errors import InputError
from explorer.scene import Scene

__all__ = ["SCENE_MODELS", "TorchScene", "adjusted_scene"]

_OFFSETS = ("position_e_m", "position_n_m", "position_u_m", "omega_rad", "phi_rad", "kappa_rad")
#: Parameter names per exterior correction model of a scene.
SCENE_MODELS: dict[str, tuple[str, ...]] = {
    "attitude": _OFFSETS,
    "attitude-drift": _OFFSETS + ("position_e_m_per_s", "position_n_m_per_s", "position_u_m_per_s",
                                  "omega_rad_per_s", "phi_rad_per_s", "kappa_rad_per_s"),
}


def adjusted_scene(scene: Scene, model: str, params: np.ndarray) -> Scene:
    """The scene with its degree-0 (and, for ``attitude-drift``, degree-1) coefficients corrected."""
    if model not in SCENE_MODELS:
        raise InputError(f"unknown scene correction model {model!r} (one of {', '.join(SCENE_MODELS)})")
    p = np.asarray(params, dtype=np.float64).reshape(-1)
    ext = scene.exterior
    pos = np.array(ext.position_coeffs, dtype=np.float64, copy=True)
    att = np.array(ext.attitude_coeffs, dtype=np.float64, copy=True)
    pos[:, 0] += p[0:3]
    att[:, 0] += p[3:6]
    if model == "attitude-drift":
        if pos.shape[1] < 2:
            pos = np.concatenate([pos, np.zeros((3, 1))], axis=1)
        if att.shape[1] < 2:
            att = np.concatenate([att, np.zeros((3, 1))], axis=1)
        pos[:, 1] += p[6:9]
        att[:, 1] += p[9:12]
    return replace(scene, exterior=replace(ext, position_coeffs=pos, attitude_coeffs=att))


def _polyval(coeffs: np.ndarray, t: torch.Tensor) -> torch.Tensor:
    """(N, K) ascending polynomials ``coeffs`` (K, D+1) of t (N,), Horner (the compiled order)."""
    c = torch.from_numpy(np.asarray(coeffs, dtype=np.float64))
    out = c[:, -1].expand(t.shape[0], -1)
    for j in range(c.shape[1] - 2, -1, -1):
        out = out * t[:, None] + c[:, j]
    return out



def radially_distorted(x: torch.Tensor, y: torch.Tensor, coefficients) -> tuple[torch.Tensor, torch.Tensor]:
    """Focal-plane (x, y) (N,) times ``1 + k1 r^2 + k2 r^4 + ...`` (the interior orientation's radial distortion,
    :attr:`explorer.geometry.interior.InteriorOrientation.radial_distortion`); unchanged without coefficients."""
    if not coefficients:
        return x, y
    r2 = x * x + y * y
    factor = torch.ones_like(r2)
    power = torch.ones_like(r2)
    for k in coefficients:
        power = power * r2
        factor = factor + k * power
    return x * factor, y * factor

class TorchScene:
    """Ground (lon, lat, h on the frame's body) -> corrected (row, col) of one MPC scene, differentiable.

    Parameters
    ----------
    scene : Scene
    model : {"attitude", "attitude-drift"}
    """

    def __init__(self, scene: Scene, model: str = "attitude") -> None:
        if model not in SCENE_MODELS:
            raise InputError(f"unknown scene correction model {model!r} (one of {', '.join(SCENE_MODELS)})")
        self.scene = scene
        self.model = model
        self.parameter_names = SCENE_MODELS[model]
        t0, t1 = scene.scanline_time(np.array([0.0, 1.0]))
        self.line_period = float(t1 - t0)
        self._cache: tuple[bytes, Scene] | None = None

    def _scene_for(self, params: np.ndarray) -> Scene:
        key = params.tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, adjusted_scene(self.scene, self.model, params))
        return self._cache[1]

    def enu(self, lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """Geodetic on the frame's body -> local ENU (N, 3) metres (the frame's formulas, in torch)."""
        frame = self.scene.frame
        a, e2 = frame.body.a_m, frame.body.e2
        lam, phi = torch.deg2rad(lon), torch.deg2rad(lat)
        sl, cl = torch.sin(phi), torch.cos(phi)
        n = a / torch.sqrt(1.0 - e2 * sl * sl)
        ecef = torch.stack([(n + h) * cl * torch.cos(lam), (n + h) * cl * torch.sin(lam), (n * (1.0 - e2) + h) * sl],
                           dim=1)
        d = ecef - torch.from_numpy(frame.origin_ecef)
        return d @ torch.from_numpy(frame.enu_to_ecef_rotation)

    def focal_plane(self, ground: torch.Tensor, t: torch.Tensor,
                    theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Distorted focal-plane (x, y) (N,) metres of ENU ``ground`` (N, 3) at times ``t`` (N,), corrections
        ``theta`` (N, P)."""
        ext = self.scene.exterior
        interior = self.scene.interior
        s = _polyval(ext.position_coeffs, t) + theta[:, 0:3]
        ang = _polyval(ext.attitude_coeffs, t) + theta[:, 3:6]
        if self.model == "attitude-drift":
            s = s + theta[:, 6:9] * t[:, None]
            ang = ang + theta[:, 9:12] * t[:, None]
        names = ("omega", "phi", "kappa")
        extra = [torch.zeros_like(t) for _ in range(3)]
        for j in ext.jitter:
            k = names.index(j.angle)
            extra[k] = extra[k] + j.amplitude_rad * torch.sin(2.0 * math.pi * j.frequency_hz * t + j.phase_rad)
        om, ph, ka = (ang[:, k] + extra[k] for k in range(3))
        so, co, sp, cp = torch.sin(om), torch.cos(om), torch.sin(ph), torch.cos(ph)
        sk, ck = torch.sin(ka), torch.cos(ka)
        # columns of R = R_x(omega) R_y(phi) R_z(kappa) (docs/conventions.md#rotations); v = R^T (P - S)
        d = ground - s
        r0 = torch.stack([cp * ck, co * sk + so * sp * ck, so * sk - co * sp * ck], dim=1)
        r1 = torch.stack([-cp * sk, co * ck - so * sp * sk, so * ck + co * sp * sk], dim=1)
        r2 = torch.stack([sp, -so * cp, co * cp], dim=1)
        vx, vy, vz = (torch.sum(r * d, dim=1) for r in (r0, r1, r2))
        scale = -interior.focal_length_m / vz
        x, y = vx * scale, vy * scale
        return radially_distorted(x, y, interior.radial_distortion)

    def _detector_x(self, y: torch.Tensor) -> torch.Tensor:
        interior = self.scene.interior
        x = torch.full_like(y, interior.along_track_offset_m)
        power = torch.ones_like(y)
        for c in interior.line_curvature:
            power = power * y
            x = x + c * power
        return x

    def project(self, lon: torch.Tensor, lat: torch.Tensor, h: torch.Tensor, params: torch.Tensor | Any
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col), each (N,), of ground points (N,); ``params`` (P,) or (N, P) (equal rows)."""
        return self.project_enu(self.enu(lon, lat, h), params)

    def project_enu(self, ground: torch.Tensor, params: torch.Tensor | Any) -> tuple[torch.Tensor, torch.Tensor]:
        """Corrected (row, col), each (N,), of local ENU ground points (N, 3); ``params`` as :meth:`project`.

        (The geodetic -> ENU conversion of :meth:`project` goes through body-fixed coordinates of planetary
        size, rounded to about 1e-9 m; this entry point avoids it.)
        """
        theta = params if isinstance(params, torch.Tensor) else torch.as_tensor(np.asarray(params, dtype=np.float64))
        theta = theta.expand(ground.shape[0], -1) if theta.ndim == 1 else theta
        p_np = theta.detach()[0].numpy().copy() if theta.shape[0] else np.zeros(len(self.parameter_names))
        if theta.shape[0] and not torch.equal(theta.detach(), theta.detach()[:1].expand_as(theta)):
            raise InputError("TorchScene.project takes one set of corrections for all points")
        scene = self._scene_for(p_np)
        row0, col0 = scene.ground_to_image(ground.detach().numpy())
        t0 = torch.from_numpy(scene.scanline_time(row0)).requires_grad_(True)
        with torch.enable_grad():  # dr/dt by autograd, also when the caller evaluates without gradients
            x, y = self.focal_plane(ground, t0, theta)
            residual = x - self._detector_x(y)
            (slope,) = torch.autograd.grad(residual.sum(), t0, create_graph=torch.is_grad_enabled())
        t = t0.detach() - residual / slope
        row = torch.from_numpy(row0) + (t - t0.detach()) / self.line_period
        _, y = self.focal_plane(ground, t, theta)
        interior = self.scene.interior
        target = y / interior.detector_pitch_m
        if not interior.column_polynomial:
            return row, target + interior.principal_column
        u = torch.from_numpy(col0 - interior.principal_column)  # one Newton step of g(u) = target from the root
        g = u.clone()
        dg = torch.ones_like(u)
        power = u.clone()
        for k, a in enumerate(interior.column_polynomial, start=2):
            dg = dg + k * a * power
            power = power * u
            g = g + a * power
        return row, u - (g - target) / dg + interior.principal_column
