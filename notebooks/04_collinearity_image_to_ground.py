# %% [markdown]
# # 04 · Collinearity; image to ground on the ellipsoid and on a DEM
#
# **Learning goals.** After this notebook you can
#
# 1. evaluate the collinearity equations of a scanline by hand and differentiate the along-track
#    residual $x(t)$ analytically (the derivative Newton-Raphson needs);
# 2. intersect a line of sight with a horizontal plane, with the ellipsoid ($h$ = const) and with
#    a DEM, and explain the difference between the local plane and the ellipsoid;
# 3. compute the relief displacement of a point and check it against the rigorous model.
#
# **Prerequisites.** Notebooks 01-03.
#
# **Estimated time.** 60 minutes.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
PRESET = "WSU"
RELIEF_M = 1500.0
N_POINTS = 300 if SMALL else 5000

# %%
import numpy as np
import plotly.graph_objects as go

from explorer.methods import create
from explorer.notebook import interactive_figure, scene_view
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
f = scene.interior.focal_length_m
p = scene.pixel_size_m
pts = simulate_points(scene, N_POINTS, kind="scp")

# %% [markdown]
# ## The collinearity equations
# For ground point $P$, perspective centre $S(t)$ and sensor → object rotation $R(t)$:
#
# $$ v = R(t)^\top \big(P - S(t)\big), \qquad x = -f\,\frac{v_x}{v_z}, \qquad y = -f\,\frac{v_y}{v_z}. $$
#
# The best scanline is the $t$ with $x(t) = x_{\text{det}}(y)$ (0 for the straight line of this
# preset).

# %%
t = pts.time + 40 * scene.timing.line_period_s  # 40 rows after the best scanline
S = scene.exterior.position(t)
R = scene.exterior.rotation(t)
v = np.einsum("nji,nj->ni", R, pts.ground - S)
x_hand, y_hand = -f * v[:, 0] / v[:, 2], -f * v[:, 1] / v[:, 2]
x, y = scene.focal_plane(pts.ground, t)
assert np.allclose(x, x_hand, rtol=0, atol=1e-15) and np.allclose(y, y_hand, rtol=0, atol=1e-15)
print(f"40 rows late, x is {np.mean(x / p):.2f} px on average (about -1 px per row, notebook 01)")

# %% [markdown]
# ## The derivative of the along-track residual
# Differentiating with the product and quotient rules,
#
# $$ \dot v = \dot R^\top (P - S) - R^\top \dot S, \qquad
# \dot x = -f\,\frac{\dot v_x v_z - v_x \dot v_z}{v_z^2}, $$
#
# $$ \dot R = \dot\omega\, R_x'(\omega) R_y R_z + \dot\varphi\, R_x R_y'(\varphi) R_z
# + \dot\kappa\, R_x R_y R_z'(\kappa), $$
#
# where $R_x'(\omega) = dR_x/d\omega$. We code it and compare it with central finite differences.

# %%
def rot(axis: int, a: np.ndarray, derivative: bool = False) -> np.ndarray:
    """Elementary rotations (N, 3, 3) about x (0), y (1), z (2), or their derivatives."""
    c, s = np.cos(a), np.sin(a)
    if derivative:
        c, s = -np.sin(a), np.cos(a)
    out = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (0, 2), (0, 1)][axis]
    out[:, i, i] = c
    out[:, j, j] = c
    sign = -1.0 if axis != 1 else 1.0  # R_y has +sin above the diagonal
    out[:, i, j] = sign * s
    out[:, j, i] = -sign * s
    if not derivative:
        out[:, 3 - i - j, 3 - i - j] = 1.0
    return out


def x_dot(scene, ground, t):
    ang, rate = scene.exterior.angles(t), scene.exterior.angle_rates(t)
    Rx, Ry, Rz = (rot(k, ang[:, k]) for k in range(3))
    dRx, dRy, dRz = (rot(k, ang[:, k], True) for k in range(3))
    Rm = Rx @ Ry @ Rz
    Rd = (rate[:, 0, None, None] * dRx @ Ry @ Rz + rate[:, 1, None, None] * Rx @ dRy @ Rz
          + rate[:, 2, None, None] * Rx @ Ry @ dRz)
    d = ground - scene.exterior.position(t)
    vv = np.einsum("nji,nj->ni", Rm, d)
    vd = np.einsum("nji,nj->ni", Rd, d) - np.einsum("nji,nj->ni", Rm, scene.exterior.velocity(t))
    return -f * (vd[:, 0] * vv[:, 2] - vv[:, 0] * vd[:, 2]) / vv[:, 2] ** 2


ang0 = scene.exterior.angles(t)
assert np.allclose(rot(0, ang0[:, 0]) @ rot(1, ang0[:, 1]) @ rot(2, ang0[:, 2]), R, atol=1e-15)
h = 1e-6
fd = (scene.along_track_residual(pts.ground, t + h) - scene.along_track_residual(pts.ground, t - h)) / (2 * h)
analytic = x_dot(scene, pts.ground, t)
rel = np.abs(analytic / fd - 1).max()
print(f"dx/dt = {analytic[0]:.6f} m/s; relative difference to finite differences: {rel:.1e}")
assert rel < 1e-6

# %% [markdown]
# ## Newton-Raphson with the analytic derivative
# $t_{k+1} = t_k - x(t_k)/\dot x(t_k)$ from the image centre's time: quadratic convergence, a few
# collinearity evaluations per point.

# %%
tk = np.zeros(len(pts))
for k in range(6):
    xk = scene.along_track_residual(pts.ground, tk)
    print(f"iteration {k}: max |x| = {np.abs(xk).max() / p:.2e} px")
    tk = tk - xk / x_dot(scene, pts.ground, tk)
row_nr = scene.row_at_time(tk)
assert np.abs(row_nr - pts.row).max() < 1e-6

# %% [markdown]
# ## The local plane is not the ellipsoid
# The scene works in a local East-North-Up frame tangent to the ellipsoid at the scene centre. A
# horizontal plane $Z$ = const of that frame rises above the ellipsoid surface away from the
# origin, by about $d^2 / (2\rho)$ ($d$ the distance from the origin, $\rho$ the Earth's radius of
# curvature). Intersecting with the ellipsoid ($h$ = const) therefore needs a small iteration
# along the ray.

# %%
corners = scene.footprint()
lon, lat, h_ell = scene.frame.enu_to_geodetic(corners)
d = np.hypot(corners[:, 0], corners[:, 1])
rise = h_ell - corners[:, 2]
print("distance from origin (km):", (d / 1e3).round(3), " ellipsoidal height - plane height (m):", rise.round(4))
rho = 6_371_000.0
assert np.allclose(rise, d**2 / (2 * rho), rtol=0.01)


def intersect_ellipsoid(row, col, h0, iterations=5):
    origin, direction = scene.rays(row, col)
    g = scene.image_to_ground(row, col, height=h0)  # start on the plane
    for _ in range(iterations):  # move along the ray by the height error over the ray's vertical slope
        _, _, hh = scene.frame.enu_to_geodetic(g)
        g = g + ((h0 - hh) / direction[:, 2])[:, None] * direction
    return g


row_c, col_c = np.array([0.0, scene.n_rows - 1.0]), np.array([0.0, scene.n_columns - 1.0])
h0 = scene.terrain.mean_height
g_ell = intersect_ellipsoid(row_c, col_c, h0)
assert np.allclose(scene.frame.enu_to_geodetic(g_ell)[2], h0, atol=1e-6)
print("plane vs ellipsoid intersection (m):", np.linalg.norm(g_ell - scene.image_to_ground(row_c, col_c, height=h0),
                                                              axis=1).round(5))

# %% [markdown]
# ## Image to ground on a DEM; relief displacement
# On a DEM the ray meets the terrain at height $Z$. Compared with its intersection at the mean
# height $\bar h$, the point moves along the ray's horizontal direction by
#
# $$ \Delta_{xy} = (Z - \bar h)\, \frac{\lVert d_{xy} \rVert}{|d_z|}. $$

# %%
hilly = build_scene(PRESET, relief_m=RELIEF_M)
rows = pts.row
cols = pts.col
g_dem = hilly.image_to_ground(rows, cols)
ok = np.isfinite(g_dem[:, 0])
g_dem, rows, cols = g_dem[ok], rows[ok], cols[ok]
on_surface = hilly.terrain.height(g_dem[:, 0], g_dem[:, 1])
assert np.allclose(on_surface, g_dem[:, 2], atol=1e-3)
g_flat = hilly.image_to_ground(rows, cols, height=hilly.terrain.mean_height)
_, direction = hilly.rays(rows, cols)
predicted = np.abs(g_dem[:, 2] - hilly.terrain.mean_height) * np.hypot(direction[:, 0], direction[:, 1]) / np.abs(
    direction[:, 2])
measured = np.hypot(*(g_dem - g_flat)[:, :2].T)
print(f"relief displacement up to {measured.max():.2f} m; formula error {np.abs(measured - predicted).max():.1e} m")
assert np.abs(measured - predicted).max() < 1e-6
back = create("exact", hilly).ground_to_image(g_dem)
assert np.abs(back.row - rows).max() < 1e-6 and np.abs(back.col - cols).max() < 1e-6

# %% [markdown]
# ## Interactive: relief displacement against the relief amplitude

# %%
def displacement_plot(relief_m=1500.0):
    sc = build_scene(PRESET, relief_m=relief_m)
    g1 = sc.image_to_ground(pts.row, pts.col)
    g0 = sc.image_to_ground(pts.row, pts.col, height=sc.terrain.mean_height)
    dxy = np.hypot(*(g1 - g0)[:, :2].T)
    fig = go.Figure(go.Scatter(x=g1[:, 2] - sc.terrain.mean_height, y=dxy / scene.ground_sample_distance()[1],
                               mode="markers", marker={"size": 3}))
    return fig.update_layout(xaxis_title="Z - mean height (m)", yaxis_title="displacement (px)", height=320,
                             title=f"relief displacement, relief {relief_m:g} m")


interactive_figure(displacement_plot, relief_m=(0.0, 3000.0, 250.0))

# %% [markdown]
# ## In 3D
# The hilly scene, with the ray of one point and the Newton-Raphson search that finds its
# scanline (the scanlines it visited, yellow first, purple last).

# %%
scene_view(hilly, point=(0.2 * hilly.n_rows, 0.7 * hilly.n_columns), method="nr")

# %% [markdown]
# ## Exercises
# 1. Show that Newton-Raphson with the analytic derivative converges quadratically: print
#    $|x_{k+1}| / |x_k|^2$ for the iterations above. What happens with a derivative that is 10 %
#    wrong?
# 2. How far from the scene centre does the plane-vs-ellipsoid drop reach 1 m? Is it a problem for
#    a 20 km WorldView scene? For a 60 km SPOT scene?
# 3. The relief displacement reaches hundreds of metres here. Compute the off-nadir angle of the
#    rays of this preset and predict the displacement of a point 1000 m above the mean height from
#    it. What would it be for the same point seen at nadir?
