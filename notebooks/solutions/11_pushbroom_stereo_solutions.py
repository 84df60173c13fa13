# %% [markdown]
# # 11 · Solutions: pushbroom stereo
#
# Worked answers to the exercises of notebook 11, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_MATCHES = 2_000 if SMALL else 50_000
COARSE_STEP, FINE_STEP = (900.0, 300.0) if SMALL else (300.0, 100.0)
MAP_SHAPE = (4, 6) if SMALL else (8, 12)

# %%
from importlib.resources import files

import numpy as np

from explorer import read_rpc
from explorer.stereo import approximation_maps, epipolar_curve, epipolar_grids, triangulate

DATA = files("explorer.assets") / "rpc"
left = read_rpc(str(DATA / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"))
right = read_rpc(str(DATA / "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML"))

# %% [markdown]
# ## Exercise 1: the bending over a wider height range
# The range grows from 2000 m to 4000 m: the square law predicts four times the deviation. (The RPCs are
# fitted for about 40..1300 m; far beyond, the curve is the RPC's extrapolation, still a smooth function.)

# %%
row0, col0 = 11_000.0, 20_000.0
base = epipolar_curve(left, right, row0, col0, np.linspace(-500.0, 1500.0, 41)).max_chord_deviation_px
wide = epipolar_curve(left, right, row0, col0, np.linspace(-1500.0, 2500.0, 41)).max_chord_deviation_px
print(f"predicted {4 * base:.4f} px, measured {wide:.4f} px")
assert abs(wide / (4 * base) - 1.0) < 0.15

# %% [markdown]
# ## Exercise 2: the step for 1e-3 px
# With $e(\Delta) = k \Delta^2$ from the fine grid, $\Delta = \sqrt{10^{-3} / k}$.

# %%
span = np.linspace(50.0, 1050.0, 5)
fine = epipolar_grids(left, right, height=550.0, step=FINE_STEP)
e_fine = np.median(approximation_maps(left, right, heights=span, shape=MAP_SHAPE, grids=fine,
                                      margin_px=200.0).maps["grid interpolation"])
step = float(np.sqrt(1e-3 / (e_fine / FINE_STEP**2)))
grid = epipolar_grids(left, right, height=550.0, step=step)
e = np.median(approximation_maps(left, right, heights=span, shape=MAP_SHAPE, grids=grid,
                                 margin_px=200.0).maps["grid interpolation"])
print(f"predicted step {step:.0f} px; median interpolation error there {e:.2e} px")
assert 0.5e-3 < e < 2e-3

# %% [markdown]
# ## Exercise 3: noisy matches
# Noise along the epipolar curve moves the point along the lines of sight (a height error of about the
# disparity-to-height ratio per pixel of noise along the curve); noise across it cannot be explained by any
# height: the lines of sight miss each other by about the noise times the ground pixel size, and each image keeps
# about half the noise as reprojection error. The right column here is mostly across the epipolar direction
# (an along-track pair: the curves run along the rows), so ray distances grow and heights move little.

# %%
rng = np.random.default_rng(1)
lon = rng.uniform(7.08, 7.27, N_MATCHES)
lat = rng.uniform(43.63, 43.72, N_MATCHES)
h = rng.uniform(100.0, 1000.0, N_MATCHES)
lrow, lcol = left.projection(lon, lat, h)
rrow, rcol = right.projection(lon, lat, h)
noise = rng.normal(0.0, 0.3, N_MATCHES)
pts = triangulate(left, right, lrow, lcol, rrow, rcol + noise)
curve = epipolar_curve(left, right, lrow[:1], lcol[:1], np.array([400.0, 600.0]))
along = abs(float(curve.direction[0, 0, 1]))  # column component of the curve's unit tangent
grids = epipolar_grids(left, right, height=550.0, step=COARSE_STEP)
predicted = grids.disparity_to_height_ratio * along * np.std(noise)
measured = np.std(pts.height - h)
print(f"height error std {measured:.3f} m (predicted {predicted:.3f} m); ray distance median "
      f"{np.median(pts.ray_distance_m):.3f} m")
assert abs(measured / predicted - 1.0) < 0.25
assert np.median(pts.ray_distance_m) > 0.01
