# %% [markdown]
# # 07 · Solutions: RPCs and generalized models
#
# Worked answers to the exercises of notebook 07, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_SCPS = 1000 if SMALL else 20000

# %%
import dataclasses

import numpy as np

from explorer.evaluate import evaluate_method
from explorer.geometry.exterior import Jitter
from explorer.methods import create
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene("WSU")

# %% [markdown]
# ## Exercise 1: only 2 height layers
# A cubic RFM has $H^2$ and $H^3$ terms (and their products): two height layers cannot determine
# them. The fit is perfect *on* the two layers — its grid residual is a fraction of a nano-pixel, so
# the fit report looks excellent — and wrong by hundreds of pixels *between* them. Four layers
# determine the cubic. Outside the fitted range the method refuses (points flagged not converged),
# because a rational function extrapolates silently. Ground truth: the exact method.

# %%
h0 = scene.terrain.mean_height
pts = simulate_points(scene, N_SCPS, kind="scp")
exact_method = create("exact", scene)
errors = {}
for layers in (2, 4):
    m = create("rfm", scene, grid=(10, 10, layers), height_range=(h0 - 100, h0 + 100))
    for dz in (-100.0, 0.0, 500.0):
        g = pts.ground.copy()
        g[:, 2] += dz
        res = m.ground_to_image(g)
        err = np.abs(res.row - exact_method.ground_to_image(g).row)
        errors[layers, dz] = (err.max(), res.converged.mean())
        print(f"{layers} layers, grid residual {m.fit_info['grid_max_px']:.1e} px; at mean height {dz:+6.0f} m: "
              f"max row error {err.max():.2e} px, converged {res.converged.mean():.2f}")
assert errors[2, -100.0][0] < 1e-6 and errors[2, 0.0][0] > 1.0  # exact on a layer, wrong between
assert errors[4, 0.0][0] < 1e-6
assert errors[2, 500.0][1] == 0.0 and errors[4, 500.0][1] == 0.0  # outside: flagged, never silent

# %% [markdown]
# ## Exercise 2: how fast may the jitter be?
# Over the image (duration $T$) a jitter of frequency $f$ makes $fT$ periods. A cubic can follow
# less than about half a period; beyond, the RFM's error approaches the jitter displacement
# itself ($D A / \mathrm{GSD}$, notebook 03).

# %%
T = scene.scanline_time(np.array([scene.n_rows - 1.0]))[0] - scene.scanline_time(np.array([0.0]))[0]
errors = {}
for f in (0.5, 1.0, 2.0, 5.0, 20.0, 60.0):
    jit = [Jitter("omega", 2e-6, f)]
    sc = dataclasses.replace(scene, exterior=dataclasses.replace(scene.exterior, jitter=jit))
    errors[f] = evaluate_method(create("rfm", sc), simulate_points(sc, N_SCPS, kind="scp")).dr_max_px
    print(f"f = {f:5.1f} Hz ({f * T:5.2f} periods over the image): rfm dr_max {errors[f]:.3f} px")
assert errors[0.5] < 0.1 < errors[20.0]

# %% [markdown]
# ## Exercise 3: why a cubic is enough for a smooth pushbroom
# Expanding $t(P)$ around the scene centre, each order is smaller than the previous by roughly the
# image duration times the relative rates (orbit curvature $\approx 10^{-3}$ rad/s, attitude rates of
# the same order, over 0.3 s). Brute force: fit polynomials of $(X, Y)$ of degree 1, 2, 3 to the exact
# rows of the check points by least squares.

# %%
pts = simulate_points(scene, N_SCPS, kind="scp")
X = (pts.ground[:, :2] - pts.ground[:, :2].mean(0)) / np.ptp(pts.ground[:, :2], axis=0)
errs = []
for degree in (1, 2, 3):
    cols = [X[:, 0] ** i * X[:, 1] ** j for i in range(degree + 1) for j in range(degree + 1 - i)]
    A = np.stack(cols, axis=1)
    coef, *_ = np.linalg.lstsq(A, pts.row, rcond=None)
    errs.append(np.abs(A @ coef - pts.row).max())
    print(f"degree {degree}: max error {errs[-1]:.2e} px")
assert errs[0] > 100 * errs[1] and errs[1] > 100 * errs[2] and errs[2] < 1e-6  # each order ~1000x smaller
