# %% [markdown]
# # 02 · Interior orientation: the detector line in the focal plane
#
# **Learning goals.** After this notebook you can
#
# 1. map a detector column to focal-plane coordinates $(x, y)$ and back;
# 2. relate focal length, detector pitch and distance to the ground sample distance (GSD) and the
#    field of view;
# 3. predict how a *curved* detector line (or an along-track offset) shifts the best scanline of
#    a point, in pixels, and check the prediction against an exact search.
#
# **Prerequisites.** Notebook 01 (rows are times, $x(t)$ crosses zero at the best scanline).
#
# **Estimated time.** 40 minutes.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
PRESET = "WSU"
N_POINTS = 60 if SMALL else 400

# %%
import dataclasses

import numpy as np
import plotly.graph_objects as go

from explorer.methods import create
from explorer.notebook import interactive_figure
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
io_ = scene.interior
print(io_)

# %% [markdown]
# ## Columns → focal plane
# Column $c$ (0-based, integer = detector centre) of a straight, evenly spaced line sits at
#
# $$ y = (c - c_0)\,p, \qquad x = x_0 + \sum_{k \ge 1} a_k\, y^k, $$
#
# with $c_0$ the principal column, $p$ the detector pitch, $x_0$ the along-track offset of the
# line and $a_k$ its curvature coefficients (all zero here: a straight line through the principal
# point).

# %%
cols = np.array([0.0, io_.principal_column, io_.n_columns - 1.0])
y = io_.column_to_y(cols)
assert np.allclose(y, (cols - io_.principal_column) * io_.detector_pitch_m, rtol=0, atol=1e-15)
assert np.allclose(io_.y_to_column(y), cols, rtol=0, atol=1e-9)
print("y of first / principal / last column (mm):", y * 1e3)

# %% [markdown]
# ## Field of view and GSD
# A line of $N$ detectors behind focal length $f$ sees the angle
# $\mathrm{FOV} = 2 \arctan\!\big(N p / (2 f)\big)$, and one detector covers about
# $\mathrm{GSD} \approx D\,p/f$ on the ground at slant distance $D$ (exactly so only for a view
# perpendicular to the ground; the oblique view of the preset stretches it by a few per cent).

# %%
fov = 2 * np.arctan(io_.n_columns * io_.detector_pitch_m / (2 * io_.focal_length_m))
centre = scene.image_to_ground(np.array([(scene.n_rows - 1) / 2]), np.array([io_.principal_column]))[0]
S = scene.exterior.position(scene.scanline_time(np.array([(scene.n_rows - 1) / 2])))[0]
D = np.linalg.norm(S - centre)
gsd_formula = D * io_.detector_pitch_m / io_.focal_length_m
gsd_along, gsd_across = scene.ground_sample_distance()
print(f"FOV {np.degrees(fov):.4f} deg, slant distance {D / 1e3:.1f} km, "
      f"GSD D p / f = {gsd_formula:.4f} m vs measured across-track {gsd_across:.4f} m")
assert abs(gsd_formula / gsd_across - 1) < 0.05

# %% [markdown]
# ## Radial distortion
# The lens maps the ideal coordinates to measured ones, $r_d = r\,(1 + k_1 r^2 + k_2 r^4)$ along
# the radius. `distort` applies it, `undistort` inverts it (iteratively); both must agree with
# the formula and with each other.

# %%
lens = dataclasses.replace(io_, radial_distortion=(50.0, 0.0))  # k1 in m^-2
xi = np.linspace(-1e-3, 1e-3, 7)
yi = np.linspace(-1.6e-2, 1.6e-2, 7)
xd, yd = lens.distort(xi, yi)
r2 = xi**2 + yi**2
assert np.allclose(xd, xi * (1 + 50.0 * r2), rtol=1e-13) and np.allclose(yd, yi * (1 + 50.0 * r2), rtol=1e-13)
xu, yu = lens.undistort(xd, yd)
print(f"undistort(distort) error: {max(np.abs(xu - xi).max(), np.abs(yu - yi).max()):.1e} m")
assert np.allclose(xu, xi, atol=1e-12) and np.allclose(yu, yi, atol=1e-12)

# %% [markdown]
# ## A curved line shifts the best scanline
# Bend the detector line by a parabola $x = a_2 y^2$ that reaches `BOW_PX` detector pitches at
# the ends of the array. A ground point now meets the line where $x(t) = a_2 y^2$ instead of 0;
# since $x$ changes by about $s$ pixels per row (notebook 01: $s \approx -1$), its best scanline
# moves by
#
# $$ \Delta r \approx \frac{x_{\text{det}}(y)}{s\,p}. $$
#
# We check the prediction against an exact search on both cameras.

# %%
BOW_PX = 2.0
points = simulate_points(scene, N_POINTS, kind="scp")


def curved(bow_px: float):
    y_end = (io_.n_columns - 1) / 2 * io_.detector_pitch_m
    a2 = bow_px * io_.detector_pitch_m / y_end**2
    return dataclasses.replace(scene, interior=dataclasses.replace(io_, line_curvature=(0.0, a2)))


bent = curved(BOW_PX)
row_straight = create("exact", scene).ground_to_image(points.ground).row
row_bent = create("exact", bent).ground_to_image(points.ground).row
t = scene.scanline_time(points.row)
dt = scene.timing.line_period_s
s = (scene.along_track_residual(points.ground, t + dt) - scene.along_track_residual(points.ground, t - dt)) / (
    2 * scene.pixel_size_m)  # pixels of x per row, per point
predicted = bent.interior.detector_x(bent.interior.column_to_y(points.col)) / (s * scene.pixel_size_m)
err = np.abs((row_bent - row_straight) - predicted)
print(f"row shift up to {np.abs(row_bent - row_straight).max():.3f} px; prediction error max {err.max():.1e} px")
assert err.max() < 0.01 * BOW_PX

# %% [markdown]
# ## Interactive: bend the line
# The best-scanline shift across the image for a bow you choose (the exact search runs on every
# change).

# %%
def shift_plot(bow_px=2.0):
    rb = create("exact", curved(bow_px)).ground_to_image(points.ground).row
    fig = go.Figure(go.Scatter(x=points.col, y=rb - row_straight, mode="markers", name="exact"))
    fig.update_layout(title=f"best-scanline shift, bow {bow_px:g} px", xaxis_title="column",
                      yaxis_title="row shift (px)", height=320)
    return fig


interactive_figure(shift_plot, bow_px=(-5.0, 5.0, 0.5))

# %% [markdown]
# ## Exercises
# 1. The along-track offset $x_0$ (`along_track_offset_m`) moves the whole line. Set it to
#    $10\,p$: by how many rows do *all* best scanlines move, and in which direction? Check with
#    `create("exact", ...)`.
# 2. Compute the swath width on the ground of `WSU` from the footprint corners and compare it with
#    $N \cdot \mathrm{GSD}$. Which is larger, and why?
# 3. A point lies at column 100 of a line with a 2-pixel bow. A student searches its best
#    scanline assuming a straight line. How large is the row error, and does it matter for a
#    1-pixel accuracy target? For a 0.01-pixel one?
