# %% [markdown]
# # 12 · Solutions: sensor refinement
#
# Worked answers to the exercises of notebook 12, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_SEEDS = 8 if SMALL else 20
N_CHECK = 200 if SMALL else 500
NOISE_PX = 0.3

# %%
from importlib.resources import files

import numpy as np

from explorer import read_rpc
from explorer.errors import InputError
from explorer.refine.adjust import refine_images
from explorer.refine.corrections import apply_correction
from explorer.refine.points_io import PointTable

rpc = read_rpc(str(files("explorer.assets") / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"))
ROWS, COLS = rpc.image_size
TRUE = np.array([4.2, 1e-4, -1e-4, -3.1, 1e-4, 1e-4])


def simulate(n, rng, noise=NOISE_PX, prefix="p", col=None):
    r, c = rng.uniform(0.02, 0.98, n) * ROWS, rng.uniform(0.02, 0.98, n) * COLS
    if col is not None:
        c = np.full(n, col)
    h = rng.uniform(*rpc.height_range(0.5), n)
    lon, lat = rpc.localization(r, c, h)[:2]
    row, c2 = apply_correction("affine", TRUE, *rpc.projection(lon, lat, h))
    return PointTable([f"{prefix}{i}" for i in range(n)], row + rng.normal(0, noise, n),
                      c2 + rng.normal(0, noise, n), lon, lat, h)


# %% [markdown]
# ## Exercise 1: eight GCPs, affine against poly2
# With $n = 16$ observations, `affine` keeps a redundancy of $16 - 6 = 10$, `poly2` only $16 - 12 = 4$: its
# twelve parameters follow the noise of the eight points, and the check points (which did not vote) see it.
# For least squares the expected check error grows with the number of unknowns $u$, roughly
# $\sigma^2 (1 + u/n)$ per coordinate at the points' own positions and more away from them.

# %%
worse = 0
for seed in range(N_SEEDS):
    rng = np.random.default_rng(100 + seed)
    gcps, check = simulate(8, rng, prefix="g"), simulate(N_CHECK, rng, prefix="c")
    affine = refine_images([rpc], model="affine", control=gcps, check=check, sigma_px=NOISE_PX, loss="linear")
    poly2 = refine_images([rpc], model="poly2", control=gcps, check=check, sigma_px=NOISE_PX, loss="linear")
    worse += poly2.check_rmse_px > affine.check_rmse_px
print(f"poly2 worse than affine on the check points in {worse} of {N_SEEDS} seeds")
assert worse >= 0.75 * N_SEEDS

# %% [markdown]
# ## Exercise 2: a wrong stated sigma
# $\sigma_0^2$ is the weighted residual square sum over the redundancy; stating $\sigma = 1$ px for 0.3 px noise
# multiplies every weighted residual by 0.3, so $\sigma_0 \approx 0.3$. The covariance
# $\sigma_0^2 \sigma^2 (A^{T} A)^{-1}$ only depends on the product $\sigma_0 \sigma$: the parameter sigmas do not
# change. $\sigma_0$ far from 1 says the stated accuracy is wrong (or the model does not fit) before anything else.

# %%
rng = np.random.default_rng(7)
gcps = simulate(30, rng, prefix="g")
right = refine_images([rpc], model="affine", control=gcps, sigma_px=NOISE_PX, loss="linear")
wrong = refine_images([rpc], model="affine", control=gcps, sigma_px=1.0, loss="linear")
print("sigma0 with the right sigma", round(right.result.sigma0, 3), " with 1 px", round(wrong.result.sigma0, 3))
assert abs(wrong.result.sigma0 - right.result.sigma0 * NOISE_PX / 1.0) < 1e-9
np.testing.assert_allclose(wrong.result.parameter_sigma, right.result.parameter_sigma, rtol=1e-8)

# %% [markdown]
# ## Exercise 3: every GCP on one column
# With $c_i$ the same for every point, the column of $A$ that multiplies `row_per_col` is a multiple of the one of
# `row_shift`: $A^{T} A$ is singular and no data can separate them (the same for `col_per_col` and `col_shift`).
# `refine_images` refuses with a one-line error naming the parameters; a shift is still determined.

# %%
line = simulate(12, np.random.default_rng(3), prefix="g", col=20_000.0)
try:
    refine_images([rpc], model="affine", control=line, sigma_px=NOISE_PX)
    message = ""
except InputError as exc:
    message = str(exc)
print(message)
assert message.startswith("degenerate configuration") and ("_per_col" in message or "_shift" in message)
shift = refine_images([rpc], model="shift", control=line, sigma_px=NOISE_PX)
assert np.all(np.isfinite(shift.result.parameter_sigma))

# %% [markdown]
# ## Exercise 4: a position error absorbed by the attitude
# A cross-orbit offset $\Delta s$ of the perspective centre shifts every line of sight's ground point by about
# $\Delta s$, which a rotation of the camera by $\delta \approx \Delta s / H$ does too (narrow field of view,
# $H$ the distance to the ground). The `attitude` model (no position parameters) therefore removes the whole
# bias: the check RMSE comes back to the noise, and the one angle that turns the lines of sight across the orbit
# takes $\Delta s / H$. On this image that angle is the **pitch** (about the sensor's $y$ axis): the agile Pleiades
# scanned it across its orbit, so its rows advance (sensor $x$) nearly perpendicular to the velocity -- checked
# below.

# %%
from explorer.refine.line_adjust import adjusted_sensor, correction_for
from explorer.sources import load_source

sensor = load_source("dimap", str(files("explorer.assets") / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML")).scene
OFFSET = 60.0  # metres across the orbit
truth = adjusted_sensor(sensor, correction_for(sensor, "position-attitude"), np.array([0.0, OFFSET, 0, 0, 0, 0]))
centre = sensor.perspective_centre(sensor.line_time(np.array([ROWS / 2])))[0]
H = float(np.linalg.norm(centre - sensor.image_to_ground(np.array([ROWS / 2]), np.array([COLS / 2]))[0]))
t_mid = sensor.line_time(np.array([ROWS / 2]))
velocity = (sensor.perspective_centre(t_mid + 0.01) - sensor.perspective_centre(t_mid))[0]
x_axis = sensor.attitude(t_mid)[0][:, 0]  # the sensor's x (rows) in local ENU
cos_x = float(x_axis @ velocity / np.linalg.norm(velocity))
print(f"angle between the rows' direction and the velocity: {np.degrees(np.arccos(cos_x)):.1f} degrees")
assert abs(cos_x) < 0.1
rng = np.random.default_rng(11)


def simulate_rigorous(n, prefix):
    r, c = rng.uniform(0.03, 0.97, n) * ROWS, rng.uniform(0.03, 0.97, n) * COLS
    g = truth.image_to_ground(r, c, height=rng.uniform(-200, 400, n))
    row, col = truth.ground_to_image(g)
    lon, lat, h = sensor.frame.enu_to_geodetic(g)
    return PointTable([f"{prefix}{i}" for i in range(n)], row + rng.normal(0, NOISE_PX, n),
                      col + rng.normal(0, NOISE_PX, n), lon, lat, h)


att = refine_images([sensor], model="attitude", control=simulate_rigorous(30, "g"),
                    check=simulate_rigorous(N_CHECK // 2, "c"), sigma_px=NOISE_PX)
rep = att.report()
angles = {q["name"]: q["value"] for q in rep["parameters"]}
largest = max(angles, key=lambda k: abs(angles[k]))
print(f"check RMSE {rep['check_rmse_px_before']:.1f} -> {rep['check_rmse_px']:.3f} px; {largest} = "
      f"{angles[largest] * 1e6:.2f} urad against Delta s / H = {OFFSET / H * 1e6:.2f} urad")
assert rep["check_rmse_px"] < 1.15 * NOISE_PX
assert largest == "pitch_rad" and abs(abs(angles[largest]) - OFFSET / H) < 0.03 * OFFSET / H
