# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 01 · Pushbroom geometry: one scanline at a time
#
# **What this teaches.** A frame camera has one exterior orientation; a linear pushbroom sensor builds
# its image line by line, and *each scanline has its own* perspective centre and attitude (the Multiple
# Projection Center model, MPC). Consequence: going from image to ground is a direct ray intersection,
# but going from ground to image is a **search** for the time (scanline) at which the detector line saw
# the point. You will
#
# 1. build a preset scene and look at its per-line exterior orientation;
# 2. evaluate the collinearity equations and see that `x(t)` (along-track focal-plane coordinate) crosses
#    zero exactly once, at the best scanline;
# 3. check that image → ground → image closes to machine precision.
#
# Conventions (pixel centre, row ↔ time, frames, rotation order): `docs/conventions.md`.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"  # CI runs a small version
PRESET = "WSU"
N_POINTS = 200 if SMALL else 5000

# %%
import numpy as np
import plotly.graph_objects as go

from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
print(scene.name, scene.shape, "line period", scene.timing.line_period_s, "s")
print("GSD (along, across) m:", scene.ground_sample_distance())

# %% [markdown]
# ## The MPC model: position and attitude are polynomials of time
# `scene.exterior.position_coeffs[k, j]` multiplies `t**j` for X, Y, Z; the attitude likewise for
# omega, phi, kappa. Over the ~0.3 s of a WorldView-2 scene the satellite moves ~2 km and rotates by
# a few hundredths of a degree.

# %%
rows = np.linspace(0, scene.n_rows - 1, 50)
t = scene.scanline_time(rows)
S = scene.exterior.position(t)
ang = np.degrees(scene.exterior.angles(t))
fig = go.Figure()
for k, name in enumerate("XYZ"):
    fig.add_scatter(x=rows, y=S[:, k] - S[0, k], name=f"{name}_S - {name}_S(row 0) [m]")
fig.update_layout(title="Perspective centre along the image", xaxis_title="row")
fig

# %%
fig = go.Figure()
for k, name in enumerate(["omega", "phi", "kappa"]):
    fig.add_scatter(x=rows, y=(ang[:, k] - ang[0, k]) * 3600, name=f"{name} - {name}(row 0) [arcsec]")
fig.update_layout(title="Attitude change along the image", xaxis_title="row")
fig

# %% [markdown]
# ## Ground → image is a search: x(t) for one ground point
# Take the ground point seen at row 1234.6, column 800.2 and evaluate the along-track focal-plane
# coordinate at every scanline time. It is zero exactly at the best scanline.

# %%
g = scene.image_to_ground(np.array([1234.6]), np.array([800.2]))
all_rows = np.arange(scene.n_rows, dtype=float)
x = scene.along_track_residual(np.repeat(g, all_rows.size, 0), scene.scanline_time(all_rows))
x_px = x / scene.pixel_size_m
k = np.argmax(np.sign(x_px[:-1]) != np.sign(x_px[1:]))
print("sign change between rows", all_rows[k], all_rows[k + 1])
go.Figure(go.Scatter(x=all_rows, y=x_px)).update_layout(
    title="x(t) of one ground point (pixels)", xaxis_title="row", yaxis_title="x / pitch")

# %% [markdown]
# ## Round trip on many points
# Simulated check points (SCPs) carry their exact row. Every collinearity residual at that row vanishes.

# %%
pts = simulate_points(scene, N_POINTS, kind="scp")
res_px = scene.along_track_residual(pts.ground, pts.time) / scene.pixel_size_m
col_err = scene.column_at_time(pts.ground, pts.time) - pts.col
print(f"{len(pts)} points: max |x| = {np.abs(res_px).max():.2e} px, max column error = {np.abs(col_err).max():.2e} px")
assert np.abs(res_px).max() < 1e-8

# %% [markdown]
# ## The 3D scene
# `./run.sh explore --preset WSU` opens the same scene in the viser explorer: trajectory, scanline planes,
# ground footprint, rays. In a notebook you can start it with `explorer.app` (see `docs/explorer.md`).
#
# ## Exercises
# 1. Switch `PRESET` to `agile`. How does the attitude curve change? Does x(t) still cross zero once?
# 2. Build `build_scene("WSU", relief_m=1000)`. Pick one image point and compare its ground point on the
#    DEM with its ground point at the mean height. How far apart are they, and why along that direction?
# 3. Why is the best scanline a *real* number and not an integer? What does a fractional row mean physically?
