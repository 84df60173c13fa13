# %% [markdown]
# # 01 · Solutions: frame camera vs pushbroom
#
# Worked answers to the exercises of notebook 01. Each answer is checked by an assertion against an
# independent value (a brute-force search, a closed form).

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"

# %%
import numpy as np

from explorer.presets import build_scene

# %% [markdown]
# ## Exercise 1: `agile`: does x(t) still cross zero once, and how linear is it?
# Brute force: evaluate $x$ on every row and count the sign changes; the crossing must be at the
# row of the image point we started from.

# %%
agile = build_scene("agile")
row0, col0 = 0.37 * agile.n_rows, 0.8 * agile.n_columns
g = agile.image_to_ground(np.array([row0]), np.array([col0]))
rows = np.arange(agile.n_rows, dtype=float)
x = agile.along_track_residual(np.repeat(g, rows.size, 0), agile.scanline_time(rows)) / agile.pixel_size_m
changes = np.flatnonzero(np.sign(x[:-1]) != np.sign(x[1:]))
print("sign changes between rows:", [(rows[k], rows[k + 1]) for k in changes])
assert len(changes) == 1 and rows[changes[0]] <= row0 <= rows[changes[0] + 1]
fit = np.polyval(np.polyfit(rows, x, 1), rows)
print(f"agile: departure from a straight line {np.abs(x - fit).max():.1f} px over the image")
wsu = build_scene("WSU")
gw = wsu.image_to_ground(np.array([row0 * wsu.n_rows / agile.n_rows]),
                         np.array([col0 * wsu.n_columns / agile.n_columns]))
rw = np.arange(wsu.n_rows, dtype=float)
xw = wsu.along_track_residual(np.repeat(gw, rw.size, 0), wsu.scanline_time(rw)) / wsu.pixel_size_m
dev_wsu = np.abs(xw - np.polyval(np.polyfit(rw, xw, 1), rw)).max()
print(f"WSU departure: {dev_wsu:.2f} px")
assert np.abs(x - fit).max() > dev_wsu  # the agile attitude bends x(t) more

# %% [markdown]
# **Answer.** Yes, one crossing, but $x(t)$ is visibly curved on `agile`: methods that assume a
# straight $x(t)$ (a single secant, the linear regression) need more iterations or more terms.

# %% [markdown]
# ## Exercise 2: duration, travel, and travel per row vs GSD
# The satellite flies at radius $r_s$, the ground is at radius $r_g$: the line of sight sweeps the
# ground slower than the satellite moves by the factor $r_g / r_s$ (for an attitude that only
# follows the orbit; the preset's attitude rates change the sweep speed, so we switch them off).

# %%
still = build_scene("WSU", attitude_rate_scale=0.0)
t = still.scanline_time(np.array([0.0, still.n_rows - 1.0]))
S = still.exterior.position(t)
duration = t[1] - t[0]
travel_per_row = np.linalg.norm(S[1] - S[0]) / (still.n_rows - 1)
gsd_along = still.ground_sample_distance()[0]
centre = still.image_to_ground(np.array([(still.n_rows - 1) / 2]), np.array([(still.n_columns - 1) / 2]))[0]
ecef = still.frame.enu_to_ecef(np.vstack([still.exterior.position(np.array([0.0]))[0], centre]))
radius_ratio = np.linalg.norm(ecef[0]) / np.linalg.norm(ecef[1])
print(f"duration {duration:.3f} s, travel {np.linalg.norm(S[1] - S[0]):.0f} m, {travel_per_row:.4f} m per row, "
      f"GSD {gsd_along:.4f} m, ratio {travel_per_row / gsd_along:.4f}, r_s / r_g = {radius_ratio:.4f}")
assert abs(travel_per_row / gsd_along / radius_ratio - 1) < 0.01

# %% [markdown]
# ## Exercise 3: what does rounding a best scanline cost on the ground?
# Row 1234.6 is the time 60 % between two exposures; rounding it to 1235 moves the ground point of
# that image column by $0.4$ along-track GSD.

# %%
g_exact = wsu.image_to_ground(np.array([1234.6]), np.array([800.2]))
g_round = wsu.image_to_ground(np.array([1235.0]), np.array([800.2]))
moved = np.linalg.norm(g_round - g_exact)
print(f"rounding moves the point by {moved:.4f} m = {moved / wsu.ground_sample_distance()[0]:.4f} GSD")
assert abs(moved / wsu.ground_sample_distance()[0] - 0.4) < 2e-3
