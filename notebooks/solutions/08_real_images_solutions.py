# %% [markdown]
# # 08 · Solutions: real images
#
# Worked answers to the exercises of notebook 08, each checked against an independent value (the
# vendor RPC).

# %% tags=["parameters"]
import os
from importlib.resources import files
from pathlib import Path

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
DATA = Path(str(files("explorer.assets") / "rpc"))  # shipped in the package (assets/rpc/PROVENANCE.md)
N_GCPS = 49 if SMALL else 200

# %%
import numpy as np

from explorer.real import compare_with_rpc, scene_from_rpc
from explorer.real.dimap import rigorous_scene_from_dimap

# %% [markdown]
# ## Exercise 1: the other datastrip
# The 2017 datastrip's RPC reproduces its rigorous model less closely than the 2018 one (its RMS is
# more than five times larger), still far below a pixel (under 0.01 px). Where: the difference map has
# **bands along the rows**: the difference changes with the row (time), rising and falling a few times
# over the image, and hardly across the columns. Measured on a 25 x 25 grid: the spread (standard
# deviation) of the per-row means is more than three times that of the per-column means, for both
# products. A difference that follows time points to the attitude and orbit (smoothed here by a cubic,
# exercise 3), which the RPC's cubic in ground coordinates cannot follow exactly.

# %%
results, spread = {}, {}
for name in ("PHRDIMAP_P1BP--2017030824934340CP.XML", "PHRDIMAP_P1BP--2018122638935449CP.XML"):
    scene, cal = rigorous_scene_from_dimap(DATA / name, n_gcps=100, n_check=300)
    cmp = compare_with_rpc(scene, n=200, layers=3, refit=False)
    results[name[15:19]] = cmp
    d = np.hypot(cmp.drow, cmp.dcol)
    assert cmp.rms_px < 0.01 and np.isclose(d.max(), cmp.max_px)
    rr, cc = np.meshgrid(np.linspace(0, scene.n_rows - 1, 25), np.linspace(0, scene.n_columns - 1, 25),
                         indexing="ij")
    g = scene.image_to_ground(rr.ravel(), cc.ravel(), height=scene.rpc.height_offset)
    r_rpc, c_rpc = scene.rpc.projection(*scene.frame.enu_to_geodetic(g))
    grid = np.hypot(r_rpc - rr.ravel(), c_rpc - cc.ravel()).reshape(rr.shape)
    spread[name[15:19]] = (grid.mean(axis=1).std(), grid.mean(axis=0).std())
    print(f"{name[15:19]}: RMS {cmp.rms_px:.5f} px, max {cmp.max_px:.5f} px; spread of the per-row means "
          f"{spread[name[15:19]][0] * 1e3:.3f} mpx, of the per-column means {spread[name[15:19]][1] * 1e3:.3f} mpx")
assert results["2017"].rms_px > 5 * results["2018"].rms_px
assert all(along_rows > 3 * across for along_rows, across in spread.values())

# %% [markdown]
# ## Exercise 2: MPC degree 3
# A third-degree polynomial in time can absorb attitude changes a quadratic cannot. Here it is
# decisive: the quadratic leaves about half a pixel on the independent check points, the cubic a
# thousandth of a pixel. Pleiades is an agile satellite whose attitude is steered during the
# acquisition; its rates are not constant over the strip, so degree 2 is not enough.

# %%
reports = {}
for degree in (2, 3):
    _, rep = scene_from_rpc(DATA / "rpc_PLEIADES.xml", n_gcps=N_GCPS, seed=0, degree=degree)
    reports[degree] = rep
    print(f"degree {degree}: GCP RMSE {rep.rmse_px:.4f} px, check RMSE {rep.check_rmse_px:.4f} px")
assert reports[3].rmse_px <= reports[2].rmse_px * 1.001  # more parameters never fit the same GCPs worse
assert reports[3].check_rmse_px < 0.1 * reports[2].check_rmse_px

# %% [markdown]
# ## Exercise 3: raw attitude samples
# Without smoothing the rigorous model differs from the RPC by more than a pixel, and the difference
# is a function of the row (time) only: the mean over each row is large while the spread across the
# swath is small. A time-only error points to the attitude (or timing) data, not to the camera.

# %%
raw, cal_raw = rigorous_scene_from_dimap(DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML", attitude_smoothing=None,
                                         n_gcps=80, n_check=100)
rows = np.linspace(0, raw.n_rows - 1, 15)
cols = np.linspace(0, raw.n_columns - 1, 7)
rr, cc = np.meshgrid(rows, cols, indexing="ij")
g = raw.image_to_ground(rr.ravel(), cc.ravel(), height=raw.rpc.height_offset)
lon, lat, h = raw.frame.enu_to_geodetic(g)
r, c = raw.rpc.projection(lon, lat, h)
dr, dc = (r - rr.ravel()).reshape(rr.shape), (c - cc.ravel()).reshape(rr.shape)
profile = np.hypot(dr.mean(axis=1), dc.mean(axis=1))
spread = np.hypot(dr.std(axis=1), dc.std(axis=1))
print(f"per-row mean difference up to {profile.max():.2f} px; spread across the swath up to {spread.max():.3f} px")
assert profile.max() > 1.0 and spread.max() < 0.1 * profile.max()
