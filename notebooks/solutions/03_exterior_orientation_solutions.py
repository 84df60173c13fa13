# %% [markdown]
# # 03 · Solutions: exterior orientation
#
# Worked answers to the exercises of notebook 03, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_POINTS = 300 if SMALL else 3000

# %%
import dataclasses

import numpy as np

from explorer.geometry.exterior import Jitter
from explorer.methods import create
from explorer.points import simulate_points
from explorer.presets import build_scene

# %% [markdown]
# ## Exercise 1: an attitude that only follows the orbit
# Then the sensor frame turns with the orbit frame: one revolution per orbit, an angular rate
# $|\dot S| / r_s$ ($r_s$ the satellite's distance from the Earth's centre).

# %%
still = build_scene("WSU", attitude_rate_scale=0.0)
preset = build_scene("WSU")
t0 = np.array([0.0])
rate = np.linalg.norm(still.exterior.angle_rates(t0))
r_s = np.linalg.norm(still.frame.enu_to_ecef(still.exterior.position(t0)))
orbit_rate = np.linalg.norm(still.exterior.velocity(t0)) / r_s
print(f"orbit-following attitude rate {rate:.4e} rad/s, |v| / r_s = {orbit_rate:.4e} rad/s, "
      f"preset rate {np.linalg.norm(preset.exterior.angle_rates(t0)):.4e} rad/s")
assert abs(rate / orbit_rate - 1) < 0.02

# %% [markdown]
# ## Exercise 2: jitter rate against the sweep rate
# The largest rate of $A \sin(2\pi f t)$ is $2\pi f A$; the line of sight sweeps the ground at
# $v / D$. While $2\pi f A < v / D$, $x(t)$ stays monotonic and a bracketing search is safe; above,
# $x(t)$ can turn back and have several zeros. Brute force over every row shows both cases.

# %%
scene = build_scene("WSU", jitter_amplitude_scale=0.0)
g = scene.image_to_ground(np.array([2000.0]), np.array([2000.0]))
D = np.linalg.norm(scene.exterior.position(t0)[0] - g[0])
sweep = np.linalg.norm(scene.exterior.velocity(t0)) / D
rows = np.arange(scene.n_rows, dtype=float)


def x_of_rows(amplitude, freq):
    jit = [Jitter("omega", amplitude, freq)]
    sc = dataclasses.replace(scene, exterior=dataclasses.replace(scene.exterior, jitter=jit))
    return sc.along_track_residual(np.repeat(g, rows.size, 0), sc.scanline_time(rows))


for amplitude, freq in ((2e-6, 20.0), (60e-6, 100.0)):
    jitter_rate = 2 * np.pi * freq * amplitude
    monotonic = bool(np.all(np.diff(x_of_rows(amplitude, freq)) < 0))
    print(f"A {amplitude * 1e6:4.0f} µrad, f {freq:5.0f} Hz: jitter rate / sweep rate = {jitter_rate / sweep:.3f}, "
          f"x(t) monotonic: {monotonic}")
    assert monotonic == (jitter_rate < sweep)

# %% [markdown]
# ## Exercise 3: why kappa jitter hardly moves points
# $\kappa$ turns the focal plane about its normal: a detector at across-track offset $y$ moves along
# track by $A\,y$, i.e. $A\,|y| / p$ pixels (divided by $|s| \approx 1$ px per row) — at the first
# column $A \cdot 2007 \approx 0.004$ px for 2 µrad.

# %%
pts = simulate_points(scene, N_POINTS, kind="scp")
A = 2e-6
kap = dataclasses.replace(scene, exterior=dataclasses.replace(scene.exterior, jitter=[Jitter("kappa", A, 20.0)]))
rows_k = create("exact", kap).ground_to_image(pts.ground).row
edge = pts.col == pts.col.min()
dt = scene.timing.line_period_s
s = (scene.along_track_residual(pts.ground, pts.time + dt) - scene.along_track_residual(pts.ground, pts.time - dt)) / (
    2 * scene.pixel_size_m)
ys = np.abs(scene.interior.column_to_y(pts.col)) / scene.pixel_size_m
lever = A * np.abs(np.sin(2 * np.pi * 20.0 * pts.time)) * ys / np.abs(s)
print(f"first column: max row shift {np.abs(rows_k - pts.row)[edge].max():.5f} px, lever-arm bound "
      f"{(A * ys / np.abs(s))[edge].max():.5f} px")
assert np.allclose(np.abs(rows_k - pts.row)[edge], lever[edge], rtol=0.05, atol=2e-5)
