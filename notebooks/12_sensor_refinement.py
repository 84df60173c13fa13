# %% [markdown]
# # 12 · Sensor refinement: removing a vendor model's bias with control points
#
# **Learning goals.** After this notebook you can
#
# 1. say why a vendor's RPC of a pushbroom image is off by a few pixels, and why that error is nearly an
#    affine map of the image (Grodecki & Dial's bias compensation);
# 2. adjust a shift, an affine or a second-order correction to ground control points (GCPs) by least squares,
#    and read the a posteriori $\sigma_0$, the parameter sigmas and their correlations;
# 3. use **check points** to tell a model that fits the noise (over-fitting) from one that fits the bias, and
#    let a robust loss flag a wrong control point;
# 4. correct a rigorous sensor's position and attitude, and explain why one image cannot tell them apart.
#
# **Prerequisites.** Notebook 08 (RPC models of real images); the least-squares normal equations.
#
# **Estimated time.** 60 minutes (the small version runs in under a minute).
#
# Conventions (0-based pixel centre, rows down): `docs/conventions.md`; the adjustment, its files and the command
# `pushbroom refine`: `docs/refine.md`.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"  # CI runs a small version
N_GCP = 12 if SMALL else 30
N_CHECK = 200 if SMALL else 1000
NOISE_PX = 0.3  # standard deviation of a measured image coordinate, pixels
SEED = 0

# %% [markdown]
# Data, shipped in the package (`explorer.assets`, read through `importlib.resources`; provenance:
# `assets/rpc/PROVENANCE.md`): the RPC of a Pleiades 1A image of 8 March 2017 (49,826 rows x 39,951 columns),
# from CNES shareloc's test data.

# %%
from importlib.resources import files

import numpy as np

from explorer import read_rpc
from explorer.notebook import interactive_figure
from explorer.panels.refine import correction_field_figure, parameter_table_figure, residual_quiver_figure
from explorer.refine.adjust import refine_images
from explorer.refine.corrections import apply_correction
from explorer.refine.points_io import PointTable

RPC_FILE = str(files("explorer.assets") / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML")  # or your own RPC
rpc = read_rpc(RPC_FILE)
ROWS, COLS = rpc.image_size
print(rpc.image_size, "heights", rpc.height_range())
assert (ROWS, COLS) == (49_826, 39_951)

# %% [markdown]
# ## Why the vendor's model is biased
# An RPC is fitted by the vendor to its rigorous model, which uses the measured orbit and attitude. Their errors
# -- a few metres of position, a few microradians of attitude -- move every line of sight of the image by
# nearly the same angle: a pushbroom camera's field of view is narrow, so a small rotation of the camera
# *shifts* the image; a drift of the attitude along the image's seconds of exposure adds a *shear* along the
# rows; a height or focal error adds a *scale*. Grodecki & Dial (2003) therefore correct the RPC in
# image space with an affine map of the model's pixel $(r, c)$:
#
# $$ r_{\text{measured}} = r + a_0 + a_1 r + a_2 c, \qquad c_{\text{measured}} = c + b_0 + b_1 r + b_2 c . $$
#
# In `explorer.refine` the six parameters are `row_shift` ($a_0$), `row_per_row` ($a_1$), `row_per_col` ($a_2$),
# `col_shift`, `col_per_row`, `col_per_col`. Here we **make** a biased image: 4.2 / -3.1 pixels of shift, a
# scale of $10^{-4}$ and a rotation of $10^{-4}$ rad (about 5 pixels at the far edge, computed below), then
# measure GCPs in it with `NOISE_PX` of noise.

# %%
TRUE = np.array([4.2, 1e-4, -1e-4, -3.1, 1e-4, 1e-4])
edge = 1e-4 * ROWS  # scale (or rotation) times the row of the far edge
print(f"scale at the far edge: {edge:.2f} px")
assert abs(edge - 5.0) < 0.1
rng = np.random.default_rng(SEED)


def simulate(n, rng, params=TRUE, noise=NOISE_PX, prefix="p"):
    """n points seen in the image: ground by localising random pixels at random heights, pixels of the biased
    model plus noise."""
    r, c = rng.uniform(0.02, 0.98, n) * ROWS, rng.uniform(0.02, 0.98, n) * COLS
    h = rng.uniform(*rpc.height_range(0.5), n)
    lon, lat = rpc.localization(r, c, h)[:2]
    row, col = apply_correction("affine", params, *rpc.projection(lon, lat, h))
    return PointTable([f"{prefix}{i}" for i in range(n)], row + rng.normal(0, noise, n),
                      col + rng.normal(0, noise, n), lon, lat, h)


gcps = simulate(N_GCP, rng, prefix="gcp")
check = simulate(N_CHECK, rng, prefix="chk")
model_row, model_col = rpc.projection(gcps.lon, gcps.lat, gcps.h)
print("GCP residuals of the vendor model (px): RMS", np.sqrt(np.mean((gcps.row - model_row) ** 2)))

# %% [markdown]
# ## Least squares, and what it tells about itself
# With the ground of the GCPs known, the correction is *linear* in its parameters: stacking the row equations,
# $\mathbf{d} = A\,\mathbf{a} + \mathbf{e}$ with rows $(1, r_i, c_i)$ of $A$ and $d_i = r_{\text{measured},i} - r_i$.
# Weighted by the stated sigma $\sigma$ of a measurement, the estimate, the a posteriori $\sigma_0$ (1 when the
# stated sigma is right) and the covariance are
#
# $$ \hat{\mathbf a} = (A^{T} A)^{-1} A^{T} \mathbf d, \qquad
#    \sigma_0^2 = \frac{\| \mathbf d - A \hat{\mathbf a} \|^2 / \sigma^2}{n - u}, \qquad
#    \Sigma_{\hat a} = \sigma_0^2 \sigma^2 (A^{T} A)^{-1}, $$
#
# with $n - u$ the redundancy (observations minus unknowns). `refine_images` solves the general, non-linear
# problem (the ground may be uncertain, or unknown for tie points) by Levenberg-Marquardt with Jacobians from
# torch's automatic differentiation; on this linear one it must give the closed form.

# %%
ref = refine_images([rpc], model="affine", control=gcps, check=check, sigma_px=NOISE_PX, loss="linear")
design = np.column_stack([np.ones(N_GCP), model_row, model_col])
a_row = np.linalg.lstsq(design, gcps.row - model_row, rcond=None)[0]
a_col = np.linalg.lstsq(design, gcps.col - model_col, rcond=None)[0]
print("adjusted:", ref.parameters)
print("lstsq:   ", np.concatenate([a_row, a_col]))
assert np.allclose(ref.parameters, np.concatenate([a_row, a_col]), rtol=1e-8, atol=1e-10)
z = (ref.parameters - TRUE) / ref.result.parameter_sigma
print("error / sigma:", np.round(z, 2), " sigma0:", round(ref.result.sigma0, 3))
assert np.all(np.abs(z) < 4.0)  # the truth lies within a few a-posteriori sigmas
parameter_table_figure(ref)

# %% [markdown]
# The correlation matrix (`ref.result.parameter_correlation`) shows why a shift and a scale are hard to tell
# apart when the GCPs sit far from the image origin: `row_shift` and `row_per_row` are correlated because every
# row is large and positive. The **check points** took no part in the fit; their RMSE is the honest accuracy of
# the adjusted model, and it should be close to the measurement noise:

# %%
report = ref.report()
print({k: round(report[k], 3) for k in ("control_rmse_px_before", "control_rmse_px", "check_rmse_px")})
assert abs(report["check_rmse_px"] - NOISE_PX) < 0.15 * NOISE_PX
correction_field_figure(ref)

# %% [markdown]
# ## What each correction can absorb: control RMSE against check RMSE
# A richer model always lowers the residuals of the points it was fitted to. Whether it is *better* only the
# check points can say: a shift leaves the scale and rotation behind (check RMSE above the noise), an affine
# removes the whole bias, a second-order polynomial (12 parameters) also starts fitting the noise of few GCPs
# (exercise 1 counts how often).

# %%
rows = []
for model in ("shift", "affine", "poly2"):
    r = refine_images([rpc], model=model, control=gcps, check=check, sigma_px=NOISE_PX, loss="linear").report()
    rows.append((model, r["control_rmse_px"], r["check_rmse_px"]))
    print(f"{model:>6}: control RMSE {r['control_rmse_px']:.3f} px, check RMSE {r['check_rmse_px']:.3f} px")
assert rows[0][2] > 2 * NOISE_PX  # a shift cannot absorb 5 px of scale and rotation
assert rows[2][1] <= rows[1][1] <= rows[0][1]  # more parameters, smaller control residuals

# %% [markdown]
# Play with it: the residual vectors of control (blue) and check (green) points before and after, for any model
# and number of GCPs (the vectors are drawn many times their length; the scale is in the titles).


# %%
def quiver_panel(model="affine", n_gcps=N_GCP):
    pts = simulate(int(n_gcps), np.random.default_rng(SEED + 1), prefix="gcp")
    chk = simulate(100, np.random.default_rng(SEED + 2), prefix="chk")
    return residual_quiver_figure(refine_images([rpc], model=model, control=pts, check=chk, sigma_px=NOISE_PX))


interactive_figure(quiver_panel, model=["shift", "affine", "poly2"], n_gcps=(8, 60, 2))

# %% [markdown]
# ## A wrong control point
# One GCP measured 25 pixels off (a mismatch, a moved landmark) drags a least-squares fit. The robust (Huber)
# loss down-weights residuals beyond `loss_scale` sigmas, and an observation whose normalised residual $s$ exceeds
# the chi-square quantile $s^2 > \chi^2_{2}(0.999) = -2 \ln(0.001) = 13.8$ is flagged an **outlier** and left
# out of the final estimate.

# %%
quantile = -2.0 * np.log(1.0 - 0.999)
print(f"chi-square(2) quantile at 0.999: {quantile:.2f}, s > {np.sqrt(quantile):.2f} sigmas")
assert abs(quantile - 13.8) < 0.05
bad = PointTable(list(gcps.ids), gcps.row.copy(), gcps.col.copy(), gcps.lon, gcps.lat, gcps.h)
bad.row[2] += 25.0
# plain least squares over every point (the closed form above), and its check RMSE
a_bad = np.concatenate([np.linalg.lstsq(design, bad.row - model_row, rcond=None)[0],
                        np.linalg.lstsq(design, bad.col - model_col, rcond=None)[0]])
chk_row, chk_col = apply_correction("affine", a_bad, *rpc.projection(check.lon, check.lat, check.h))
plain_check = np.sqrt(np.mean(((check.row - chk_row) ** 2 + (check.col - chk_col) ** 2) / 2))
robust = refine_images([rpc], model="affine", control=bad, check=check, sigma_px=NOISE_PX, loss="huber")
linear = refine_images([rpc], model="affine", control=bad, check=check, sigma_px=NOISE_PX, loss="linear")
print("robust loss flags:", [bad.ids[i] for i in np.flatnonzero(robust.result.outlier)])
print("least squares, then the test, flags:", [bad.ids[i] for i in np.flatnonzero(linear.result.outlier)])
print("check RMSE (px): least squares", round(plain_check, 3), " robust", round(robust.check_rmse_px, 3))
assert 2 in np.flatnonzero(robust.result.outlier)
assert robust.check_rmse_px < plain_check

# %% [markdown]
# Testing the residuals of a plain least-squares fit may also flag good points: the wrong one pulled the fit
# towards itself and pushed its neighbours' residuals up ("swamping"). The robust loss looks at the residuals
# of a fit the wrong point could not drag. A good point can still be flagged now and then: at the probability
# 0.999, one good point in a thousand lies beyond the threshold by chance (look at its residual: a few sigmas,
# not tens).

# %% [markdown]
# ## A physical model: the position and attitude of a rigorous sensor
# The bias of a vendor RPC comes from the orbit and attitude measured on board. With the image's rigorous model
# (here the Pleiades DIMAP metadata of the same image, `explorer.sources.load_source("dimap", ...)`) the
# adjustment can correct those directly: offsets of the perspective centre along / across the orbit and radially
# (metres, the orbital axes at the image's middle time) and of the attitude (roll, pitch, yaw, radians), applied
# to every sample of the position and attitude tables (`explorer.refine.line_adjust`; the model stays the same
# kind of model, so the adjusted one is written as a small sidecar JSON by `pushbroom refine --dimap`).
#
# A pushbroom camera's field of view is narrow (Pleiades: about 1.7 degrees), so moving the perspective centre
# by $\Delta s$ across the line of sight moves the image almost exactly like turning the camera by
#
# $$ \delta \approx \frac{\Delta s}{H}, $$
#
# $H$ the distance to the ground (about 700 km here: 40 m is about 57 microradians). Over one flat-ish image,
# position and attitude offsets are therefore nearly **the same correction**: the attitude alone absorbs a
# position error, and an adjustment of both finds a combination, with correlations close to $\pm 1$ and large
# sigmas. Below, the rigorous model is biased by known position and attitude offsets and GCPs are measured in it.

# %%
from explorer.panels.refine import trajectory_figure
from explorer.refine.line_adjust import adjusted_sensor, correction_for
from explorer.refine.trajectory import refinement_trajectory
from explorer.sources import load_source

sensor = load_source("dimap", RPC_FILE).scene  # the rigorous model of the DIMAP file (it also holds the RPC)
TRUE_LINE = np.array([40.0, -25.0, 10.0, 2e-5, -1.5e-5, 1e-5])  # along, cross, radial m; roll, pitch, yaw rad
truth = adjusted_sensor(sensor, correction_for(sensor, "position-attitude"), TRUE_LINE)
centre = sensor.perspective_centre(sensor.line_time(np.array([ROWS / 2])))[0]
ground = sensor.image_to_ground(np.array([ROWS / 2]), np.array([COLS / 2]))[0]
H = float(np.linalg.norm(centre - ground))
print(f"distance to the ground H = {H / 1e3:.0f} km: 40 m is {40.0 / H * 1e6:.0f} microradians")
assert 600e3 < H < 900e3


def simulate_rigorous(n, rng, prefix):
    """n GCPs: ground seen by the biased model at random pixels and heights, its pixels plus noise."""
    r, c = rng.uniform(0.03, 0.97, n) * ROWS, rng.uniform(0.03, 0.97, n) * COLS
    g = truth.image_to_ground(r, c, height=rng.uniform(-200, 400, n))
    row, col = truth.ground_to_image(g)
    lon, lat, h = sensor.frame.enu_to_geodetic(g)
    return PointTable([f"{prefix}{i}" for i in range(n)], row + rng.normal(0, NOISE_PX, n),
                      col + rng.normal(0, NOISE_PX, n), lon, lat, h)


rng_line = np.random.default_rng(SEED + 3)
gcps_line, check_line = simulate_rigorous(N_GCP, rng_line, "gcp"), simulate_rigorous(N_CHECK // 2, rng_line, "chk")
fits = {}
for model in ("attitude", "position-attitude"):
    fits[model] = refine_images([sensor], model=model, control=gcps_line, check=check_line, sigma_px=NOISE_PX)
    r = fits[model].report()
    print(f"{model:>17}: control RMSE {r['control_rmse_px_before']:.1f} -> {r['control_rmse_px']:.3f} px, "
          f"check RMSE {r['check_rmse_px']:.3f} px, sigma0 {r['sigma0']:.2f}")
    assert r["check_rmse_px"] < 1.25 * NOISE_PX  # both remove the whole bias of the check points
both = fits["position-attitude"]
z = (both.parameters - TRUE_LINE) / both.result.parameter_sigma
corr = both.result.parameter_correlation
print("error / sigma:", np.round(z, 2))
print("largest |correlation| between a position and an attitude parameter:", round(np.abs(corr[:3, 3:]).max(), 4))
assert np.all(np.abs(z) < 3.0) and np.abs(corr[:3, 3:]).max() > 0.99
parameter_table_figure(both)

# %% [markdown]
# The trajectory the adjustment found (`explorer.refine.trajectory`; the explorer draws it in its 3D scene with
# `pushbroom explore --dimap FILE --gcps gcps.csv`, the displacement exaggerated by a stated factor): the
# perspective centre moved by the length of the fitted offset at every line, the camera turned by the angle of the
# fitted roll, pitch and yaw.

# %%
track = refinement_trajectory(both)
p = {q["name"]: q["value"] for q in both.report()["parameters"]}
moved = np.linalg.norm([p["along_m"], p["cross_m"], p["radial_m"]])
print(track.summary(), f"fitted offset {moved:.2f} m")
assert np.allclose(np.linalg.norm(track.displacement_m, axis=1), moved, rtol=1e-9)
trajectory_figure(both)

# %% [markdown]
# ## Exercises
# 1. With only 8 GCPs, fit `affine` and `poly2` for 20 different seeds. In how many of them is the check RMSE of
#    `poly2` larger than that of `affine`? Explain with the redundancy $n - u$.
# 2. State the wrong sigma: adjust with `sigma_px=1.0` while the noise is 0.3 px. What does $\sigma_0$ become,
#    and do the parameter sigmas change? Why is $\sigma_0$ the first number to look at?
# 3. Put every GCP on one image column (same `col`, different rows). Which parameter can the adjustment no
#    longer determine, what does `refine_images` say, and which model still works?
# 4. Bias the rigorous model by a position offset only (60 m across the orbit, no attitude error). Adjust the
#    `attitude` model: how close to the noise is the check RMSE, and which attitude angle took the offset? Compare
#    the angle with $\Delta s / H$.
