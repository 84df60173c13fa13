"""Stereo pairs shared by the stereo tests: the public Pleiades pair (tests/data/rpc, PROVENANCE.md there),
a synthetic pair of constant-velocity scenes seen from two azimuths in two local frames, and independent truths
(rpcm; closed-form collinearity of the synthetic pair)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import rpcm

from explorer.geometry.exterior import ExteriorOrientation
from explorer.geometry.frames import LocalFrame
from explorer.geometry.rotations import axis_angle_matrix, opk_from_rotation
from explorer.presets import build_scene
from explorer.scene import Scene

RPC_DIR = Path(__file__).resolve().parents[1] / "data" / "rpc"
PHR_LEFT = "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001"
PHR_RIGHT = "PHR1B_P_201709281038393_SEN_PRG_FC_178609-001"
#: (left, right) file pairs of the public Pleiades pair: the DIMAP RPC XML and the OSSIM .geom twins.
PHR_PAIRS = {
    "xml": (RPC_DIR / f"RPC_{PHR_LEFT}.XML", RPC_DIR / f"RPC_{PHR_RIGHT}.XML"),
    "geom": (RPC_DIR / f"{PHR_LEFT}.geom", RPC_DIR / f"{PHR_RIGHT}.geom"),
}


def rpcm_pair() -> tuple[rpcm.RPCModel, rpcm.RPCModel]:
    """The public pair read by rpcm (from the DIMAP XML files)."""
    left, right = PHR_PAIRS["xml"]
    return rpcm.rpc_from_rpc_file(str(left)), rpcm.rpc_from_rpc_file(str(right))


def rpcm_localise(model: rpcm.RPCModel, row: np.ndarray, col: np.ndarray, h: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The exact inverse of rpcm's projection: rpcm's own iterative localisation (it stops near 1e-5 px), then
    Newton steps on rpcm's projection with a central-difference Jacobian until the residual is below 1e-9 px."""
    row, col, h = (np.asarray(v, dtype=np.float64) for v in np.broadcast_arrays(row, col, h))
    lon, lat = model.localization_iterative((col - model.col_offset) / model.col_scale,
                                            (row - model.row_offset) / model.row_scale,
                                            (h - model.alt_offset) / model.alt_scale)
    lon = lon * model.lon_scale + model.lon_offset
    lat = lat * model.lat_scale + model.lat_offset
    d = 1e-6
    for _ in range(6):
        c0, r0 = model.projection(lon, lat, h)
        c1, r1 = model.projection(lon + d, lat, h)
        c2, r2 = model.projection(lon, lat + d, h)
        c3, r3 = model.projection(lon - d, lat, h)
        c4, r4 = model.projection(lon, lat - d, h)
        j = np.stack([np.stack([(r1 - r3) / (2 * d), (r2 - r4) / (2 * d)], -1),
                      np.stack([(c1 - c3) / (2 * d), (c2 - c4) / (2 * d)], -1)], -2)
        e = np.stack([row - r0, col - c0], -1)
        step = np.linalg.solve(j, e[..., None])[..., 0]
        lon = lon + step[..., 0]
        lat = lat + step[..., 1]
    c0, r0 = model.projection(lon, lat, h)
    assert np.max(np.hypot(r0 - row, c0 - col)) < 1e-9
    return lon, lat


def synthetic_pair(azimuth_deg: float = 90.0) -> tuple[Scene, Scene]:
    """Two constant-velocity, constant-attitude scenes (the ``linear`` preset, 13 degrees off nadir) looking at
    the same ground from azimuths ``azimuth_deg`` apart; the right one is expressed in a local frame 0.02 degrees
    north-east of the left one's (its orbit and attitude transformed through ECEF), so the pair has two frames."""
    left = build_scene("linear")
    q = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), np.radians(azimuth_deg))
    frame_b = LocalFrame(left.frame.lat0_deg + 0.02, left.frame.lon0_deg + 0.02, 0.0)
    # A-frame -> B-frame: rotation m and translation
    m = frame_b.enu_to_ecef_rotation.T @ left.frame.enu_to_ecef_rotation
    shift = frame_b.ecef_to_enu(left.frame.origin_ecef[None, :])[0]
    pos = left.exterior.position_coeffs.copy()
    pos_b = m @ q @ pos
    pos_b[:, 0] += shift
    r_a = left.exterior.rotation(np.array([0.0]))[0]
    omega, phi, kappa = opk_from_rotation(m @ q @ r_a)
    att = np.array([[float(omega)], [float(phi)], [float(kappa)]])
    right = replace(left, name="linear-right", exterior=ExteriorOrientation(pos_b, att), frame=frame_b)
    return left, right


def closed_form_pixels(scene: Scene, ground_ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of ECEF points in a constant-velocity, constant-attitude scene with a straight detector
    through the principal point: the scanline solves the linear equation ``(R^T (P - S0 - V t))_x = 0``."""
    p = scene.frame.ecef_to_enu(ground_ecef)
    s0 = scene.exterior.position_coeffs[:, 0]
    v = scene.exterior.position_coeffs[:, 1]
    r = scene.exterior.rotation(np.array([0.0]))[0]
    a = (p - s0) @ r  # rows: R^T (P - S0)
    b = r.T @ v
    t = a[:, 0] / b[0]
    u = a - t[:, None] * b[None, :]
    f = scene.interior.focal_length_m
    y = -f * u[:, 1] / u[:, 2]
    row = t / scene.timing.line_period_s + scene.timing.reference_row
    col = y / scene.interior.detector_pitch_m + scene.interior.principal_column
    return row, col
