# %% [markdown]
# # 03 · Exterior orientation: MPC polynomials, attitude and jitter
#
# **Learning goals.** After this notebook you can
#
# 1. write the Multiple Projection Center (MPC) model: position and attitude as polynomials of
#    time, and evaluate their derivatives analytically;
# 2. build the rotation matrix $R = R_x(\omega) R_y(\varphi) R_z(\kappa)$ by hand and check it;
# 3. predict the image displacement caused by attitude jitter of a given amplitude, and see
#    which angle moves points along and which across track.
#
# **Prerequisites.** Notebooks 01 and 02; rotation matrices.
#
# **Estimated time.** 45 minutes.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
PRESET = "WSU"
N_POINTS = 500 if SMALL else 5000
JITTER_RAD = 2e-6
JITTER_HZ = 20.0

# %%
import dataclasses

import numpy as np
import plotly.graph_objects as go

from explorer.geometry.exterior import Jitter
from explorer.methods import create
from explorer.notebook import interactive_figure
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET, jitter_amplitude_scale=0.0)  # the preset without its jitter
ext = scene.exterior
print("position coefficients (m, m/s, m/s^2):\n", ext.position_coeffs)
print("attitude coefficients (rad, rad/s, rad/s^2):\n", ext.attitude_coeffs)

# %% [markdown]
# ## Position and velocity
# $$ S(t) = \sum_{j=0}^{D} a_j\, t^j, \qquad \dot S(t) = \sum_{j=1}^{D} j\, a_j\, t^{j-1}. $$
# The analytic velocity must match central finite differences
# $\big(S(t+h) - S(t-h)\big) / 2h$, whose error is $O(h^2)$.

# %%
t = scene.scanline_time(np.linspace(0, scene.n_rows - 1, 7))
h = 1e-3
v_fd = (ext.position(t + h) - ext.position(t - h)) / (2 * h)
v = ext.velocity(t)
print("speed (m/s):", np.linalg.norm(v, axis=1).round(2))
assert np.allclose(v, v_fd, rtol=1e-9, atol=1e-6)
powers = np.arange(ext.position_coeffs.shape[1])
v_hand = np.stack([np.polyval((ext.position_coeffs[k] * powers)[1:][::-1], t) for k in range(3)], axis=1)
assert np.allclose(v, v_hand, rtol=1e-12)

# %% [markdown]
# ## Attitude and the rotation matrix
# The angles are polynomials too (plus jitter sinusoids, below); the sensor → object rotation is
#
# $$ R = R_x(\omega)\,R_y(\varphi)\,R_z(\kappa), \quad
# R_x(\omega) = \begin{pmatrix} 1 & 0 & 0 \\ 0 & \cos\omega & -\sin\omega \\ 0 & \sin\omega & \cos\omega
# \end{pmatrix}, \dots $$

# %%
def rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


omega, phi, kappa = ext.angles(t[:1])[0]
R_hand = rx(omega) @ ry(phi) @ rz(kappa)
R = ext.rotation(t[:1])[0]
print(np.round(R, 6))
assert np.allclose(R, R_hand, atol=1e-15)
assert np.allclose(R.T @ R, np.eye(3), atol=1e-15) and np.isclose(np.linalg.det(R), 1.0)
rates_fd = (ext.angles(t + h) - ext.angles(t - h)) / (2 * h)
assert np.allclose(ext.angle_rates(t), rates_fd, rtol=1e-6, atol=1e-12)

# %% [markdown]
# ## Jitter
# A jitter term adds $A \sin(2\pi f t + \phi_0)$ to one angle. A tilt of $A$ radians moves the
# line of sight on the ground by about $D\,A$ metres ($D$ the slant distance), i.e.
#
# $$ \Delta \approx \frac{D\,A}{\mathrm{GSD}} \text{ pixels.} $$
#
# We add jitter to *only* the exterior orientation (`dataclasses.replace`: the interior and the
# line timing stay identical, so rows stay comparable) and measure the shift of every check
# point's best scanline and column with an exact search.

# %%
points = simulate_points(scene, N_POINTS, kind="scp")
centre = points.ground.mean(axis=0)
D = np.linalg.norm(ext.position(np.array([0.0]))[0] - centre)
gsd = scene.ground_sample_distance()[0]
predicted = D * JITTER_RAD / gsd


def with_jitter(angle: str, amplitude: float, freq: float):
    jit = [Jitter(angle, amplitude, freq)] if amplitude else []
    return dataclasses.replace(scene, exterior=dataclasses.replace(ext, jitter=jit))


shifts = {}
for angle in ("omega", "phi", "kappa"):
    res = create("exact", with_jitter(angle, JITTER_RAD, JITTER_HZ)).ground_to_image(points.ground)
    shifts[angle] = (np.abs(res.row - points.row).max(), np.abs(res.col - points.col).max())
    print(f"{angle:5s}: max row shift {shifts[angle][0]:6.3f} px, max column shift {shifts[angle][1]:6.3f} px")
print(f"predicted D A / GSD = {predicted:.3f} px")
big = max(shifts["omega"][0], shifts["phi"][0])
assert abs(big / predicted - 1) < 0.1  # along track: one of omega / phi, as the flight direction decides

# %% [markdown]
# ## Interactive: jitter along the image
# Row shift of the check points against their row, for an amplitude, frequency and angle you
# choose.

# %%
def jitter_plot(angle="omega", amplitude_urad=2.0, frequency_hz=20.0):
    j = with_jitter(angle, amplitude_urad * 1e-6, frequency_hz)
    res = create("exact", j).ground_to_image(points.ground)
    fig = go.Figure(go.Scatter(x=points.row, y=res.row - points.row, mode="markers", marker={"size": 3},
                               name="row shift"))
    fig.add_scatter(x=points.row, y=res.col - points.col, mode="markers", marker={"size": 3}, name="column shift")
    return fig.update_layout(xaxis_title="row", yaxis_title="shift (px)", height=330,
                             title=f"{angle} jitter {amplitude_urad:g} µrad at {frequency_hz:g} Hz")


interactive_figure(jitter_plot, angle=["omega", "phi", "kappa"], amplitude_urad=(0.0, 10.0, 0.5),
                   frequency_hz=(1.0, 100.0, 1.0))

# %% [markdown]
# ## Exercises
# 1. With `attitude_rate_scale=0` the attitude only follows the orbit. Build that scene and show
#    that the angle rates are then those of the orbit frame alone. How large are they compared with
#    the preset's?
# 2. Jitter at 20 Hz with an amplitude of 2 µrad: what is the largest *rate* of the angle, and how
#    does it compare with the angular rate at which the scanline sweeps the ground ($v/D$)? Why
#    does that ratio matter for search methods that assume $x(t)$ is monotonic?
# 3. Why does `kappa` jitter hardly move the points at all? Compute the displacement of the point
#    at the first column predicted by the lever arm ($\kappa$ rotates about the line of sight).
