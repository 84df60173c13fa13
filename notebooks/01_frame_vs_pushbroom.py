# %% [markdown]
# # 01 · Frame camera vs pushbroom: time, frames and the scanline
#
# **Learning goals.** After this notebook you can
#
# 1. say why a pushbroom image has one exterior orientation *per row* (the Multiple Projection
#    Center model, MPC) where a frame image has one for the whole image;
# 2. convert a row to its exposure time and back, and explain what a *fractional* row means;
# 3. show numerically that treating a pushbroom image as a frame image is wrong by hundreds of
#    pixels, and that ground → image therefore becomes a **search** for the best scanline.
#
# **Prerequisites.** Python and numpy; the pinhole camera (collinearity) from a photogrammetry
# or computer-vision course.
#
# **Estimated time.** 45 minutes (the small version runs in seconds).
#
# Conventions (pixel centre, row ↔ time, frames, rotation order): `docs/conventions.md`. The
# lecturer's guide for this course: `docs/course.md`.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"  # CI runs a small version
PRESET = "WSU"
N_POINTS = 200 if SMALL else 5000

# %%
import numpy as np
import plotly.graph_objects as go

from explorer.notebook import interactive_figure, scene_view
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
print(scene.name, "rows x columns:", scene.shape, " line period:", scene.timing.line_period_s, "s")
print("GSD (along, across) m:", scene.ground_sample_distance())

# %% [markdown]
# ## Rows are times
# A frame camera exposes every pixel at once. A linear array exposes **one line** at a time; the
# satellite's motion sweeps it over the ground. Row $r$ (0-based, integer = pixel centre) is
# exposed at
#
# $$ t(r) = (r - r_0)\,\Delta t, $$
#
# with $\Delta t$ the line period and $r_0$ the reference row (time 0). A row of 1234.6 is the
# instant 60 % of the way between the exposures of rows 1234 and 1235.

# %%
rows = np.array([0.0, 1234.6, scene.n_rows - 1.0])
t = scene.scanline_time(rows)
t_formula = (rows - scene.timing.reference_row) * scene.timing.line_period_s
print("t(r) =", t, "s")
assert np.allclose(t, t_formula, rtol=0, atol=1e-15)
assert np.allclose(scene.row_at_time(t), rows, rtol=0, atol=1e-9)  # and back
print(f"the whole image takes {t[-1] - t[0]:.3f} s")

# %% [markdown]
# ## One perspective centre per row
# In the MPC model the perspective centre $S(t)$ and the attitude $(\omega, \varphi, \kappa)(t)$
# are polynomials of time (notebook 03). Over the fraction of a second of a scene the satellite
# moves kilometres: every row has its own projection centre.

# %%
rr = np.linspace(0, scene.n_rows - 1, 50)
S = scene.exterior.position(scene.scanline_time(rr))
travel = np.linalg.norm(S[-1] - S[0])
print(f"perspective centre moves {travel:.0f} m between the first and last row "
      f"({travel / (scene.n_rows - 1):.2f} m per row)")
fig = go.Figure()
for k, name in enumerate("XYZ"):
    fig.add_scatter(x=rr, y=S[:, k] - S[0, k], name=f"{name}_S - {name}_S(row 0) [m]")
fig.update_layout(title="Perspective centre along the image", xaxis_title="row", height=350)
fig

# %% [markdown]
# ## The misconception: "use the centre row's orientation for the whole image"
# Take the ground points seen at the centre column of several rows and project them with the
# **centre row's** perspective centre and attitude, as a frame camera would. The along-track
# focal-plane coordinate $x$ should be 0 for a point on the detector line; in pixels it is
# $x / p$ ($p$ the detector pitch).

# %%
rows_check = np.linspace(0, scene.n_rows - 1, 9)
cols_check = np.full_like(rows_check, (scene.n_columns - 1) / 2)
ground = scene.image_to_ground(rows_check, cols_check)
t_centre = scene.scanline_time(np.array([(scene.n_rows - 1) / 2]))
x_frame = scene.along_track_residual(ground, np.repeat(t_centre, ground.shape[0])) / scene.pixel_size_m
x_true = scene.along_track_residual(ground, scene.scanline_time(rows_check)) / scene.pixel_size_m
for r, xf, xt in zip(rows_check, x_frame, x_true, strict=True):
    print(f"row {r:7.1f}: frame-camera x = {xf:9.2f} px, pushbroom x at its own row = {xt:.1e} px")
assert np.abs(x_true).max() < 1e-6
# the frame model's error grows about one pixel per row away from the centre
slope = np.polyfit(rows_check - (scene.n_rows - 1) / 2, x_frame, 1)[0]
print(f"frame-model error: {slope:.4f} px per row")
assert 0.9 < abs(slope) < 1.1

# %% [markdown]
# ## Ground → image is a search
# For one ground point, evaluate $x(t)$ at every scanline: it is (almost) linear in $t$ and
# crosses zero once, at the best scanline. Image → ground is a direct ray intersection; ground →
# image needs the zero of $x(t)$.

# %%
g = scene.image_to_ground(np.array([1234.6]), np.array([800.2]))
all_rows = np.arange(scene.n_rows, dtype=float)
x_px = scene.along_track_residual(np.repeat(g, all_rows.size, 0), scene.scanline_time(all_rows)) / scene.pixel_size_m
k = int(np.argmax(np.sign(x_px[:-1]) != np.sign(x_px[1:])))
print("sign change between rows", all_rows[k], "and", all_rows[k + 1])
assert all_rows[k] == 1234.0

# %% [markdown]
# ## Interactive: x(t) of a point you choose
# Move the sliders: the zero crossing follows the row of the point you picked; the column
# changes the slope only slightly (the scanline plane is tilted by the attitude).

# %%
def x_of_t(row=1234.6, col=800.0):
    gp = scene.image_to_ground(np.array([row]), np.array([col]))
    xs = scene.along_track_residual(np.repeat(gp, all_rows.size, 0), scene.scanline_time(all_rows))
    fig = go.Figure(go.Scatter(x=all_rows, y=xs / scene.pixel_size_m, name="x(t) / pitch"))
    fig.add_vline(x=row, line_dash="dot", annotation_text=f"best scanline {row:.1f}")
    fig.add_hline(y=0, line_color="black")
    return fig.update_layout(xaxis_title="row", yaxis_title="x (px)", height=320,
                             title=f"x(t) of the ground point of ({row:.1f}, {col:.1f})")


interactive_figure(x_of_t, row=(0.0, float(scene.n_rows - 1), 0.5), col=(0.0, float(scene.n_columns - 1), 1.0))

# %% [markdown]
# ## Round trip on many points
# Simulated check points (SCPs) carry their exact row. Every collinearity residual at that row
# vanishes.

# %%
pts = simulate_points(scene, N_POINTS, kind="scp")
res_px = scene.along_track_residual(pts.ground, pts.time) / scene.pixel_size_m
col_err = scene.column_at_time(pts.ground, pts.time) - pts.col
print(f"{len(pts)} points: max |x| = {np.abs(res_px).max():.2e} px, max column error = {np.abs(col_err).max():.2e} px")
assert np.abs(res_px).max() < 1e-8 and np.abs(col_err).max() < 1e-6

# %% [markdown]
# ## The 3D scene, inline
# The same scene as `./run.sh explore --preset WSU`, drawn by the explorer's own builders: the
# satellite track (compressed distance), the planes of the first, middle and last scanlines and
# of the chosen point's best scanline, the ground footprint, and the ray of the chosen point.
# Drag to rotate; the scroll wheel zooms.

# %%
scene_view(scene, point=(1234.6, 800.2))

# %% [markdown]
# ## Exercises
# 1. Switch `PRESET` to `agile` (large attitude rates). Does $x(t)$ still cross zero exactly once?
#    How far from linear is it (fit a line and look at the residual in pixels)?
# 2. How many seconds does the whole `WSU` image take, and how far does the satellite travel in
#    that time? Compare the travel per row with the along-track GSD: why are they different?
# 3. Why is the best scanline a *real* number and not an integer? What is the physical meaning
#    of row 1234.6, and what error would rounding it to 1235 make on the ground?
