# %% [markdown]
# # 04 · Solutions: collinearity, ellipsoid and DEM
#
# Worked answers to the exercises of notebook 04, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_POINTS = 200 if SMALL else 2000

# %%
import numpy as np

from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene("WSU")
pts = simulate_points(scene, N_POINTS, kind="scp")
h = 1e-7


def x_dot(t):
    """Derivative of the along-track residual by central differences (the notebook derives it analytically)."""
    return (scene.along_track_residual(pts.ground, t + h) - scene.along_track_residual(pts.ground, t - h)) / (2 * h)


# %% [markdown]
# ## Exercise 1: quadratic convergence, and a derivative 10 % wrong
# Newton's error obeys $e_{k+1} \approx \frac{x''}{2x'} e_k^2$: the ratio $|x_{k+1}| / |x_k|^2$ stays
# bounded. With the derivative scaled by $1.1$, the step undershoots by $1/1.1$ and the error
# contracts *linearly* by $1 - 1/1.1 = 0.0909$ per iteration.

# %%
def newton(scale, iterations):
    t = np.zeros(len(pts))
    out = []
    for _ in range(iterations):
        x = scene.along_track_residual(pts.ground, t)
        out.append(np.abs(x).max())
        t = t - x / (scale * x_dot(t))
    return np.array(out) / scene.pixel_size_m


exact_d = newton(1.0, 3)
print("|x_k| (px):", exact_d, " |x_k+1| / |x_k|^2:", exact_d[1:] / exact_d[:-1] ** 2)
assert exact_d[2] < 1e-6 * exact_d[1]
wrong = newton(1.1, 6)
ratios = wrong[1:] / wrong[:-1]
print("10 % wrong derivative: |x_k+1| / |x_k| =", ratios.round(4))
assert np.allclose(ratios[1:4], 1 - 1 / 1.1, atol=0.01)

# %% [markdown]
# ## Exercise 2: where does the plane drift 1 m from the ellipsoid?
# $d^2 / (2\rho) = 1$ m gives $d = \sqrt{2\rho} \approx 3.57$ km; a 20 km scene reaches $d \approx 14$ km
# at its corners (about 15 m), a 60 km SPOT scene about 42 km (about 140 m). A local frame is fine for
# the geometry (everything is computed in it consistently); heights must be converted with
# `frame.enu_to_geodetic`, never read off $Z$.

# %%
rho = 6_371_000.0
d1 = np.sqrt(2 * rho * 1.0)
_, _, h_ell = scene.frame.enu_to_geodetic(np.array([[d1, 0.0, 0.0], [0.0, d1, 0.0]]))
print(f"d = {d1 / 1e3:.3f} km: ellipsoidal height of the plane point {h_ell.round(4)} m")
assert np.allclose(h_ell, 1.0, rtol=0.01)

# %% [markdown]
# ## Exercise 3: the off-nadir angle sets the relief displacement
# A straight ray with direction $d$ moves horizontally by $\tan\theta = \lVert d_{xy}\rVert / |d_z|$
# metres per metre of height. Check against two plane intersections 1000 m apart.

# %%
rc, cc = np.array([(scene.n_rows - 1) / 2]), np.array([(scene.n_columns - 1) / 2])
_, direction = scene.rays(rc, cc)
tan_theta = np.hypot(direction[0, 0], direction[0, 1]) / abs(direction[0, 2])
h0 = scene.terrain.mean_height
moved = np.linalg.norm((scene.image_to_ground(rc, cc, height=h0 + 1000) - scene.image_to_ground(rc, cc, height=h0))[
    0, :2])
print(f"off-nadir angle {np.degrees(np.arctan(tan_theta)):.2f} deg: 1000 tan(theta) = {1000 * tan_theta:.2f} m, "
      f"measured {moved:.2f} m; at nadir: 0 m")
assert abs(moved - 1000 * tan_theta) < 1e-6
