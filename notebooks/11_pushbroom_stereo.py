# %% [markdown]
# # 11 · Pushbroom stereo: triangulation and epipolar curves that are not lines
#
# **Learning goals.** After this notebook you can
#
# 1. triangulate matched pixels of two pushbroom images (any two sensors) and read the ray distance and
#    reprojection error a good match must have;
# 2. explain why the epipolar "line" of a pushbroom pair is a **curve** (each scanline has its own perspective
#    centre) and measure how much it bends over a real Pleiades pair;
# 3. say what an epipolar resampling grid (as OTB, shareloc and CARS make them) approximates, and how its
#    interpolation error depends on the grid step.
#
# **Prerequisites.** Notebooks 01 (rows are times), 04 (image to ground) and 08 (RPC models of real images).
#
# **Estimated time.** 50 minutes (the small version runs in under a minute).
#
# Conventions (0-based pixel centre, ellipsoidal heights): `docs/conventions.md`; the stereo API and its checks:
# `docs/stereo.md`.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"  # CI runs a small version
N_MATCHES = 2_000 if SMALL else 200_000
COARSE_STEP, FINE_STEP = (900.0, 300.0) if SMALL else (300.0, 100.0)
MAP_SHAPE = (4, 6) if SMALL else (10, 16)

# %% [markdown]
# Data, shipped in the package (`explorer.assets`, read through `importlib.resources`, so the notebook runs from
# any folder; provenance: `assets/rpc/PROVENANCE.md`): the public Pleiades 1B pair of CNES shareloc, two images of
# Nice taken **35 s apart** on 28 September 2017 from one orbit (an along-track stereo pair), each 22,940 rows x
# 40,000 columns, described by its RPC.

# %%
from importlib.resources import files

import numpy as np

from explorer import read_rpc
from explorer.notebook import interactive_figure
from explorer.panels.stereo import approximation_figure, epipolar_curve_figure
from explorer.stereo import approximation_maps, epipolar_curve, epipolar_grids, triangulate

DATA = files("explorer.assets") / "rpc"  # any path to your own pair works as well
LEFT_FILE = str(DATA / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML")
RIGHT_FILE = str(DATA / "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML")
left, right = read_rpc(LEFT_FILE), read_rpc(RIGHT_FILE)
print("left ", left.image_size, "heights", left.height_range())
print("right", right.image_size, "heights", right.height_range())

# %% [markdown]
# ## Triangulation
# A match is a left pixel $p_L$ and a right pixel $p_R$ that see the same ground point $X$. Each pixel has a line
# of sight; two lines in space rarely meet exactly, so the point is the one whose projections are closest to
# the two pixels:
#
# $$ \hat X = \arg\min_X \; \lVert P_L(X) - p_L \rVert^2 + \lVert P_R(X) - p_R \rVert^2 , $$
#
# with $P_L, P_R$ the sensors' own ground-to-image functions. `triangulate` starts from the closest approach of
# the two lines of sight and solves this by Gauss-Newton, so an exact match gives an exact point even where a
# line of sight is not straight. Let us make exact matches: ground points at known positions and heights,
# projected into both images.

# %%
rng = np.random.default_rng(0)
lon = rng.uniform(7.08, 7.27, N_MATCHES)
lat = rng.uniform(43.63, 43.72, N_MATCHES)
h = rng.uniform(100.0, 1000.0, N_MATCHES)
lrow, lcol = left.projection(lon, lat, h)
rrow, rcol = right.projection(lon, lat, h)
points = triangulate(left, right, lrow, lcol, rrow, rcol)
print("valid:", points.valid.mean(), " largest height error (m):", np.max(np.abs(points.height - h)))
print("largest ray distance (m):", points.ray_distance_m.max(), " reprojection (px):", points.reprojection_px.max())
assert np.max(np.abs(points.height - h)) < 1e-3 and np.max(points.ray_distance_m) < 1e-3

# %% [markdown]
# ## The epipolar curve
# For one left pixel $p$, every height $h$ gives one ground point on its line of sight, $L(p, h)$, and its
# projection into the right image is a candidate match:
#
# $$ q(h) = P_R\big(L(p, h)\big). $$
#
# For two frame cameras $q(h)$ runs along a straight line (the epipolar line). A pushbroom image is exposed one
# row at a time: the ground point at another height is seen by the right image at another **row**, i.e. another
# time, from another perspective centre and attitude. So $q(h)$ bends. Its distance from the chord between its
# two ends is
#
# $$ d(h) = \frac{(q(h) - q_0) \times (q_1 - q_0)}{\lVert q_1 - q_0 \rVert} . $$

# %%
row0, col0 = 11_000.0, 20_000.0
heights = np.linspace(-500.0, 1500.0, 21)
curve = epipolar_curve(left, right, row0, col0, heights)
chord = np.array([curve.row[-1] - curve.row[0], curve.col[-1] - curve.col[0]])
by_hand = ((curve.row - curve.row[0]) * chord[1] - (curve.col - curve.col[0]) * chord[0]) / np.linalg.norm(chord)
assert np.allclose(by_hand, curve.chord_deviation_px, atol=1e-9)
# every point of the curve is a match at its height: triangulating it gives that height back (heights outside the
# RPCs' validity domain, 40..1120 m, are flagged rather than returned)
back = triangulate(left, right, np.full(heights.size, row0), np.full(heights.size, col0), curve.row, curve.col)
inside = (heights >= 100.0) & (heights <= 1000.0)
assert back.valid[inside].all() and np.max(np.abs(back.height[inside] - heights[inside])) < 1e-3
print("flags outside the domain:", back.flag_counts())
print(f"the curve spans {np.linalg.norm(chord):.0f} px for 2 km of height; largest distance from its chord "
      f"{curve.max_chord_deviation_px:.4f} px")

# %% [markdown]
# A few hundredths of a pixel over two kilometres: small, but a matcher that searches along the chord is that
# far off, and the bending grows fast with the height range. Over a short range the curve is a parabola in $h$,
# so its largest distance from the chord grows with the **square** of the range: halving the range divides it
# by about four.

# %%
half = epipolar_curve(left, right, row0, col0, np.linspace(0.0, 1000.0, 21))
ratio = curve.max_chord_deviation_px / half.max_chord_deviation_px
print(f"range 2000 m / 1000 m: deviation ratio {ratio:.2f} (quadratic law: 4)")
assert 3.5 < ratio < 4.5

# %% [markdown]
# Move the pixel and the height range; the right panel exaggerates the bending across the chord.

# %%
def curve_panel(row=11_000.0, col=20_000.0, top_height=1500.0, exaggeration=2000.0):
    c = epipolar_curve(left, right, row, col, np.linspace(-500.0, top_height, 21))
    return epipolar_curve_figure(c, exaggeration=exaggeration)


interactive_figure(curve_panel, row=(0.0, 22_939.0, 1000.0), col=(0.0, 39_999.0, 1000.0),
                   top_height=(0.0, 4000.0, 250.0), exaggeration=[1.0, 100.0, 2000.0, 10_000.0])

# %% [markdown]
# ## Epipolar resampling grids, and how wrong each approximation is
# Stereo tools resample both images so that matches lie on the same row: the **grids** map each epipolar-image
# position to a left and a right sensor position, one node every `step` pixels, read bilinearly in between.
# `epipolar_grids` builds them as shareloc does (following the local epipolar direction at a chosen height); the
# **disparity-to-height ratio** says how many metres one pixel of disparity is.
#
# `approximation_maps` compares, over the left image, the exact curve with: the straight line through two
# heights, a locally affine camera, the grid read bilinearly (how far off its epipolar row the true match lies),
# and the grid's interpolation alone at its height. A bilinear interpolation of a smooth function errs by
# $\tfrac18 \max|f''|\,\Delta^2$: the interpolation error should fall with the **square** of the step.

# %%
coarse = epipolar_grids(left, right, height=550.0, step=COARSE_STEP)
fine = epipolar_grids(left, right, height=550.0, step=FINE_STEP)
print(f"epipolar image {coarse.epipolar_size}, disparity-to-height {coarse.disparity_to_height_ratio:.3f} m/px")
span = np.linspace(50.0, 1050.0, 9)
maps_coarse = approximation_maps(left, right, heights=span, shape=MAP_SHAPE, grids=coarse, margin_px=200.0)
maps_fine = approximation_maps(left, right, heights=span, shape=MAP_SHAPE, grids=fine, margin_px=200.0)
for name, s in maps_fine.summary().items():
    print(f"{name:20s} median {s['median_px']:.2e} px   max {s['max_px']:.2e} px")
interp_ratio = (np.median(maps_coarse.maps["grid interpolation"]) / np.median(maps_fine.maps["grid interpolation"]))
print(f"interpolation error, step {COARSE_STEP:g} / step {FINE_STEP:g}: {interp_ratio:.1f} "
      f"(square law: {(COARSE_STEP / FINE_STEP) ** 2:.0f})")
assert 0.5 * (COARSE_STEP / FINE_STEP) ** 2 < interp_ratio < 2.0 * (COARSE_STEP / FINE_STEP) ** 2
approximation_figure(maps_fine)

# %% [markdown]
# ## Exercises
# 1. Using the square law, predict the largest chord deviation of the curve of pixel (11000, 20000) over
#    -1500..2500 m from its value over -500..1500 m, then compute it.
# 2. From the two grids above, predict the step at which the median interpolation error reaches 1e-3 px; build
#    the grid at that step and measure it.
# 3. Add 0.3 px of noise to the right columns of the matches. How large are the ray distances, and how large the
#    height errors? Explain the ratio of height error to noise with the disparity-to-height ratio and the
#    direction of the epipolar curve in the right image.
