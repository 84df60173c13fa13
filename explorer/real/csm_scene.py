"""USGS CSM line-scan camera -> the project's pushbroom :class:`~explorer.scene.Scene`.

Beyond the papers.  :func:`scene_from_isd` turns an ISD (:func:`explorer.real.csm.read_isd`) into
an MPC scene -- polynomials of the scanline time for the perspective centre and the
``(omega, phi, kappa)`` attitude, a detector line in the focal plane -- so that every registered
method, the bench, the 3D view and the residual maps run on it:

* frame: a local east-north-up frame at the body-fixed point under the image centre (on the
  file's ellipsoid, planetodetic normal); ``metadata["csm"]`` keeps the body radii, that origin
  and the axes (:func:`enu_to_body_fixed`, :func:`body_fixed_to_enu`); ``scene.frame`` is the same
  frame on the ISD's ellipsoid (``frame.body``, :func:`explorer.real.csm_sensor.csm_body`);
* pixels: scene ``(row, col)`` = CSM ``(line - 0.5, sample - 0.5)``
  (``docs/conventions.md#usgs-csm-line-scan-isds``);
* time: ``t = (row - reference_row) * line_period`` with the image's mean line period;
* interior: the CSM detector line mapped through ``focal2pixel`` and the inverse of the
  optical distortion, expressed exactly as the project's interior model with no lens
  distortion: the across-track coordinate as a polynomial of the column
  (``column_polynomial``, degree ``interior_degree``) and the along-track coordinate as a
  polynomial of it (``line_curvature``);
* exterior: the CSM centres and camera rotations sampled along the image (plus a margin) and
  fitted by polynomials of degree ``degree`` (default 3: the compiled fixed evaluator applies),
  optionally plus ``harmonics`` sinusoids per attitude angle (the project's jitter terms) for the
  attitude wander the polynomials cannot follow.

The conversion is an approximation of the CSM camera by the MPC model -- a *stand-in*: the camera itself is
:class:`explorer.real.csm_sensor.CsmScene`, the truth of the explorer and the bench; ``metadata["csm_fit"]``
reports its size in pixels on check points the CSM camera generates (row: along-track
residual / pitch; column: difference), and so does the log of ``pushbroom scene from-isd``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from explorer.errors import SceneFileError
from explorer.geometry.exterior import ExteriorOrientation, Jitter, LineTiming
from explorer.geometry.frames import LocalFrame
from explorer.geometry.rotations import opk_from_rotation
from explorer.geometry.terrain import FlatTerrain
from explorer.real.csm_camera import CsmCamera, read_isd
from explorer.real.csm_sensor import csm_body, csm_interior
from explorer.scene import Scene

__all__ = ["body_fixed_to_enu", "enu_to_body_fixed", "scene_from_camera", "scene_from_isd"]


def _enu_axes(point: np.ndarray, a: float, b: float) -> tuple[np.ndarray, float, float]:
    """ENU axes (columns) at a body-fixed point, from the ellipsoid normal; planetodetic lat/lon (deg)."""
    n = np.array([point[0] / a**2, point[1] / a**2, point[2] / b**2])
    n /= np.linalg.norm(n)
    lat = np.arcsin(np.clip(n[2], -1, 1))
    lon = np.arctan2(n[1], n[0])
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    axes = np.array([[-so, -sl * co, cl * co], [co, -sl * so, cl * so], [0.0, cl, sl]])
    return axes, float(np.degrees(lat)), float(np.degrees(lon))


def _scaled_fit(x: np.ndarray, y: np.ndarray, degree: int, scale: float) -> np.ndarray:
    """Ascending polynomial coefficients in ``x`` fitted by least squares in ``x / scale`` (conditioning)."""
    c = np.polynomial.polynomial.polyfit(x / scale, y, degree)
    return c / scale ** np.arange(degree + 1)


def body_fixed_to_enu(scene: Scene, xyz: np.ndarray) -> np.ndarray:
    """Body-fixed metres (N, 3) -> the scene's local ENU metres (N, 3) (scenes from :func:`scene_from_isd`)."""
    meta = scene.metadata["csm"]
    return (np.asarray(xyz, dtype=np.float64) - np.asarray(meta["origin_body_fixed_m"])) @ np.asarray(meta["enu_axes"])


def enu_to_body_fixed(scene: Scene, enu: np.ndarray) -> np.ndarray:
    """Inverse of :func:`body_fixed_to_enu`."""
    meta = scene.metadata["csm"]
    return np.asarray(enu, dtype=np.float64) @ np.asarray(meta["enu_axes"]).T + np.asarray(meta["origin_body_fixed_m"])


def scene_from_isd(path: str | Path, *, degree: int = 3, interior_degree: int = 7, margin_rows: float = 64.0,
                   n_check: int = 2000, seed: int = 0, interpolation: str = "usgscsm", harmonics: int = 0) -> Scene:
    """MPC :class:`~explorer.scene.Scene` of a CSM line-scan ISD (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The ISD (JSON).
    degree : int
        Degree of the position and attitude polynomials of the scanline time (default 3).
    interior_degree : int
        Degree of the column and detector-line polynomials (default 7).
    margin_rows : float
        The exterior is fitted over the image +- this many rows.
    n_check : int
        CSM check points (random image points at random heights in the ISD's reference range)
        on which the fit is reported.
    seed : int
        Seed of the check points.
    interpolation : {"usgscsm", "tables"}
        Passed to :func:`~explorer.real.csm.read_isd`.
    harmonics : int
        Sinusoids per angle (the project's attitude jitter terms, frequencies ``k / T`` for
        ``k = 1 .. harmonics`` over the fitted span ``T``) fitted to what the polynomials leave of the
        attitude (default 0: none).  They follow attitude wander the polynomials cannot (CTX: 0.48 ->
        about 0.1 px with 20), at the cost of slower methods (more than 8 terms leave the compiled
        fixed evaluator).

    Returns
    -------
    Scene
        ``metadata["csm"]`` (body, frame), ``metadata["csm_fit"]`` (max/rms row and column
        residuals against the CSM camera, pixels).
    """
    camera = read_isd(path, interpolation=interpolation)
    return scene_from_camera(camera, degree=degree, interior_degree=interior_degree, margin_rows=margin_rows,
                             n_check=n_check, seed=seed, harmonics=harmonics)


def scene_from_camera(camera: CsmCamera, *, degree: int = 3, interior_degree: int = 7, margin_rows: float = 64.0,
                      n_check: int = 2000, seed: int = 0, harmonics: int = 0) -> Scene:
    """:func:`scene_from_isd` for an already read :class:`~explorer.real.csm.CsmCamera`."""
    if degree < 1 or interior_degree < 1 or harmonics < 0:
        raise ValueError(f"degree and interior_degree must be >= 1 and harmonics >= 0, got {degree}, "
                         f"{interior_degree}, {harmonics}")
    cam = camera
    n_rows = cam.n_lines
    # ---- frame: ENU at the ground point of the image centre (or the nearest image point that sees the body)
    line0, sample0 = cam.anchor_point()  # the image centre, or the nearest image point that sees the body
    centre = cam.image_to_ground([line0], [sample0], 0.0)
    if not centre.hit[0]:
        raise SceneFileError(f"{cam.source}: the image centre does not see the body")
    origin = centre.ground[0]
    axes, lat0, lon0 = _enu_axes(origin, cam.semi_major_m, cam.semi_minor_m)
    # ---- interior: the detector line, undistorted, in the project's sensor axes (shared with CsmScene)
    interior, s_matrix = csm_interior(cam, interior_degree)
    # ---- timing: mean line period, reference row at the centre
    t_first, t_last = cam.line_time(np.array([0.5, n_rows - 0.5]))
    period = float((t_last - t_first) / (n_rows - 1))
    ref_row = 0.5 * (n_rows - 1)
    t_ref = float(cam.line_time(np.array([ref_row + 0.5]))[0])
    timing = LineTiming(period, ref_row)
    # ---- exterior: sampled and fitted
    rows = np.linspace(-0.5 - margin_rows, n_rows - 0.5 + margin_rows, 40 * (degree + 1 + 2 * harmonics) + 1)
    tau = (rows - ref_row) * period
    t_csm = cam.line_time(rows + 0.5)
    centres, rot = cam.exterior(t_csm)
    pos_enu = (centres - origin) @ axes
    r_enu = np.einsum("ji,njk,kl->nil", axes, rot, s_matrix)  # sensor -> ENU
    om, ph, ka = opk_from_rotation(r_enu)
    angles = np.unwrap(np.stack([om, ph, ka]), axis=1)
    t_scale = float(np.max(np.abs(tau)))
    pos_c = np.stack([_scaled_fit(tau, pos_enu[:, k], degree, t_scale) for k in range(3)])
    att_c = np.stack([_scaled_fit(tau, angles[k], degree, t_scale) for k in range(3)])
    jitter = []
    if harmonics:
        span = float(tau[-1] - tau[0])
        freqs = np.arange(1, harmonics + 1) / span
        basis = [np.ones_like(tau)] + [(tau / t_scale) ** j for j in range(1, degree + 1)]
        for f in freqs:
            basis += [np.sin(2 * np.pi * f * tau), np.cos(2 * np.pi * f * tau)]
        design = np.column_stack(basis)
        for k, name in enumerate(("omega", "phi", "kappa")):
            coef, *_ = np.linalg.lstsq(design, angles[k], rcond=None)
            att_c[k] = coef[: degree + 1] / t_scale ** np.arange(degree + 1)
            for j, f in enumerate(freqs):
                a, b = coef[degree + 1 + 2 * j], coef[degree + 2 + 2 * j]  # a sin + b cos = A sin(w t + p)
                jitter.append(Jitter(name, float(np.hypot(a, b)), float(f), float(np.arctan2(b, a))))
    exterior = ExteriorOrientation(pos_c, att_c, jitter)
    meta = {
        "source": "usgscsm-isd", "isd": str(cam.source), "sensor": cam.metadata.get("sensor"),
        "platform": cam.metadata.get("platform"),
        "csm": {"semi_major_m": cam.semi_major_m, "semi_minor_m": cam.semi_minor_m,
                "origin_body_fixed_m": origin.tolist(), "enu_axes": axes.tolist(),
                "lat0_deg": lat0, "lon0_deg": lon0, "time_reference_s": t_ref,
                "pixel_convention": "scene (row, col) = CSM (line - 0.5, sample - 0.5)"},
    }
    scene = Scene(name=str(Path(cam.source).stem), interior=interior, exterior=exterior, timing=timing,
                  n_rows=n_rows, terrain=FlatTerrain(0.0), frame=LocalFrame(lat0, lon0, 0.0, body=csm_body(cam)),
                  metadata=meta)
    if n_check:
        scene.metadata["csm_fit"] = fit_report(scene, cam, n_check, seed)
    return scene


def fit_report(scene: Scene, cam: CsmCamera, n: int = 2000, seed: int = 0) -> dict:
    """Row and column residuals (pixels) of the MPC scene against CSM check points.

    Random CSM image points at random heights in the camera's reference height range go to the
    ground through the CSM camera; the scene's along-track residual at the CSM row (divided by
    the pitch) and its column there are compared with the CSM row and column.
    """
    rng = np.random.default_rng(seed)
    lines = rng.uniform(0.0, cam.n_lines, n)
    samples = rng.uniform(0.0, cam.n_samples, n)
    lo, hi = cam.height_range_m
    g = cam.image_to_ground(lines, samples, rng.uniform(lo, hi, n))
    enu = body_fixed_to_enu(scene, g.ground[g.hit])
    rows, cols = lines[g.hit] - 0.5, samples[g.hit] - 0.5
    t = scene.scanline_time(rows)
    dr = scene.along_track_residual(enu, t) / scene.pixel_size_m
    dc = scene.column_at_time(enu, t) - cols
    return {"n": int(enu.shape[0]), "row_max_px": float(np.max(np.abs(dr))),
            "row_rms_px": float(np.sqrt(np.mean(dr**2))), "col_max_px": float(np.max(np.abs(dc))),
            "col_rms_px": float(np.sqrt(np.mean(dc**2)))}
