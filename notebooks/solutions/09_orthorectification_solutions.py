# %% [markdown]
# # 09 · Solutions: orthorectification
#
# Worked answers to the exercises of notebook 09, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_POINTS = 2000 if SMALL else 20000

# %%
import numpy as np

from explorer.evaluate import evaluate_method
from explorer.methods import create
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene("WSU", relief_m=800.0)
rng = np.random.default_rng(0)
rows = rng.uniform(0, scene.n_rows - 1, N_POINTS)  # output pixels land anywhere: uniform fractions
cols = rng.uniform(0, scene.n_columns - 1, N_POINTS)
ground = scene.image_to_ground(rows, cols)
ok = np.isfinite(ground[:, 0])
ground, rows, cols = ground[ok], rows[ok], cols[ok]

# %% [markdown]
# ## Exercise 1: `ss` in the orthoimage
# SS returns the nearest line too, so its row error is the same rounding error, RMS $1/\sqrt{12}$.
# The column is computed by the collinearity *at the rounded row*; the scanline is tilted on the
# ground, so the column error is the rounding error times $dc/dr$ along the ground point's path — a
# small, correlated error, not uniform.

# %%
sub = slice(0, 300)  # SS evaluates every line: a few hundred points
ss = create("ss", scene).ground_to_image(ground[sub])
bws = create("bws", scene).ground_to_image(ground[sub])
assert np.array_equal(ss.row, bws.row)
res = create("bws", scene).ground_to_image(ground)
e = res.row - rows
print(f"row error RMS {np.sqrt(np.mean(e**2)):.4f} px (1/sqrt(12) = {1 / np.sqrt(12):.4f}); "
      f"column error RMS {np.sqrt(np.mean((res.col - cols) ** 2)):.4f} px")
assert abs(np.sqrt(np.mean(e**2)) - 1 / np.sqrt(12)) < 0.01

# %% [markdown]
# ## Exercise 2: the largest relief displacement
# $\Delta = |Z - \bar h| \tan\theta$ (notebook 04). We compare the formula with the image-point
# difference of the DEM point and the mean-plane point of the same ground position, converted to
# ground metres with the GSD.

# %%
_, direction = scene.rays(rows, cols)
tan_theta = np.hypot(direction[:, 0], direction[:, 1]) / np.abs(direction[:, 2])
predicted = np.abs(ground[:, 2] - scene.terrain.mean_height) * tan_theta
g_back = scene.image_to_ground(rows, cols, height=scene.terrain.mean_height)
measured = np.hypot(*(g_back - ground)[:, :2].T)
print(f"largest displacement {predicted.max():.1f} m = {predicted.max() / scene.ground_sample_distance()[1]:.0f} px")
assert np.allclose(measured, predicted, rtol=1e-9, atol=1e-6)

# %% [markdown]
# ## Exercise 3: the cost of a 10 000 x 10 000 orthoimage
# Collinearity evaluations = pixels x CE per point (measured here on check points).

# %%
pts = simulate_points(build_scene("WSU"), 500, kind="scp")
for name in ("bws", "nr", "exact"):
    ev = evaluate_method(create(name, build_scene("WSU")), pts)
    total = 1e8 * ev.ce_evals_per_point
    print(f"{name:6s}: {ev.ce_evals_per_point:5.2f} CE per point -> {total:.2e} CE")
    if name == "bws":
        assert abs(ev.ce_evals_per_point - np.log2(3996)) < 4  # ~log2(rows) bisections
    if name == "exact":
        assert ev.ce_evals_per_point == 1.0
