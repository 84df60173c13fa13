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
# # 08 · Real images: the Pleiades rigorous model against its vendor RPC
#
# **Learning goals.** After this notebook you can
#
# 1. read a vendor RPC file, convert its 1-based DIMAP convention to 0-based pixel centres, and
#    evaluate it by hand;
# 2. build a *rigorous* Pleiades line-scan model from the DIMAP ephemeris and attitude tables and
#    measure how closely the vendor RPC reproduces it;
# 3. run the papers' pipeline (GCPs from the RPC, MPC space resection, simulated points) and the
#    best-scanline methods on the recovered geometry.
#
# **Prerequisites.** Notebooks 03, 05 and 07.
#
# **Estimated time.** 60 minutes.
#
# Data: CNES shareloc test data (Pleiades DIMAP v1.4 and v2 metadata), see
# `tests/data/rpc/PROVENANCE.md`. Conventions: `docs/rpc.md`, `docs/real_images.md`.

# %% tags=["parameters"]
import os
from pathlib import Path

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
ROOT = Path.cwd().parent
DATA = ROOT / "tests" / "data" / "rpc"
RPC_FILE = DATA / "rpc_PLEIADES.xml"
DIMAP_FILE = DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML"
N_GCPS = 49 if SMALL else 400
N_SCPS = 2000 if SMALL else 200000
METHODS = ["nr", "bws-interp", "lrm", "prm", "exact"]

# %%
import xml.etree.ElementTree as ET

import numpy as np
import plotly.graph_objects as go

from explorer.evaluate import evaluate_method
from explorer.methods import available, create
from explorer.notebook import interactive_figure, scene_view
from explorer.points import simulate_points
from explorer.real import compare_with_rpc, scene_from_rpc
from explorer.real.dimap import rigorous_scene_from_dimap
from explorer.rpc import read_rpc
from explorer.rpc.model import evaluate_rpc00b_polynomial

rpc = read_rpc(RPC_FILE)
print(type(rpc).__name__, rpc.source_format, "image size", rpc.image_size)

# %% [markdown]
# ## 1-based files, 0-based pixels
# DIMAP counts pixels from 1; this project uses 0-based pixel centres everywhere
# (`docs/conventions.md`), so the readers subtract 1 from the offsets. Then
#
# $$ r = r_0 + r_s \frac{N_r(L, P, H)}{D_r(L, P, H)} $$
#
# with the normalised coordinates of notebook 07. We check both against the raw file.

# %%
root = ET.parse(RPC_FILE).getroot()
line_off = float(root.find(".//LINE_OFF").text)
samp_off = float(root.find(".//SAMP_OFF").text)
assert rpc.row_offset == line_off - 1 and rpc.col_offset == samp_off - 1
lon = rpc.lon_offset + 0.3 * rpc.lon_scale * np.linspace(-1, 1, 5)
lat = rpc.lat_offset + 0.3 * rpc.lat_scale * np.linspace(1, -1, 5)
h = np.full(5, rpc.height_offset)
Ln, Pn, Hn = (lon - rpc.lon_offset) / rpc.lon_scale, (lat - rpc.lat_offset) / rpc.lat_scale, (
    h - rpc.height_offset) / rpc.height_scale
row_hand = rpc.row_offset + rpc.row_scale * evaluate_rpc00b_polynomial(rpc.row_num, Ln, Pn, Hn) / (
    evaluate_rpc00b_polynomial(rpc.row_den, Ln, Pn, Hn))
col_hand = rpc.col_offset + rpc.col_scale * evaluate_rpc00b_polynomial(rpc.col_num, Ln, Pn, Hn) / (
    evaluate_rpc00b_polynomial(rpc.col_den, Ln, Pn, Hn))
row, col = rpc.projection(lon, lat, h)
assert np.allclose(row, row_hand, atol=1e-8) and np.allclose(col, col_hand, atol=1e-8)
print("rows:", row.round(3), "\ncols:", col.round(3))

# %% [markdown]
# ## The rigorous Pleiades model against its vendor RPC
# `rigorous_scene_from_dimap` builds the line-scan model from the DIMAP ephemeris and attitude
# (interior calibrated on the RPC); `compare_with_rpc` intersects a grid of image points with
# height planes and sends them back through the vendor RPC. CNES states the RPC reproduces its own
# rigorous model to a few thousandths of a pixel.

# %%
rigorous, calibration = rigorous_scene_from_dimap(DIMAP_FILE, n_gcps=100, n_check=300)
cmp = compare_with_rpc(rigorous, n=200, layers=3, refit=False)
print(f"rigorous vs vendor RPC: RMS {cmp.rms_px:.4f} px, max {cmp.max_px:.4f} px over {cmp.n_points} points")
assert cmp.rms_px < 0.01 and cmp.max_px < 0.03

# %% [markdown]
# ### Interactive: where they differ, height by height

# %%
def difference_map(height_m=float(rigorous.rpc.height_offset)):
    rr, cc = np.meshgrid(np.linspace(0, rigorous.n_rows - 1, 25), np.linspace(0, rigorous.n_columns - 1, 25),
                         indexing="ij")
    g = rigorous.image_to_ground(rr.ravel(), cc.ravel(), height=height_m)
    lo, la, hh = rigorous.frame.enu_to_geodetic(g)
    r2, c2 = rigorous.rpc.projection(lo, la, hh)
    d = np.hypot(r2 - rr.ravel(), c2 - cc.ravel())
    fig = go.Figure(go.Heatmap(z=d.reshape(rr.shape) * 1e3, x=cc[0], y=rr[:, 0], colorbar={"title": "mpx"}))
    return fig.update_layout(title=f"|rigorous - RPC| at {height_m:.0f} m (milli-pixels)", height=380,
                             yaxis_autorange="reversed", xaxis_title="column", yaxis_title="row")


lo_h, hi_h = rigorous.rpc.height_range(1.0)
interactive_figure(difference_map, height_m=(float(lo_h), float(hi_h), float((hi_h - lo_h) / 8)))

# %% [markdown]
# ### The real scene in 3D
# The rigorous Pleiades scene, drawn by the explorer's builders, with the Newton-Raphson search of
# one point.

# %%
scene_view(rigorous, point=(0.25 * rigorous.n_rows, 0.6 * rigorous.n_columns), method="nr")

# %% [markdown]
# ## The papers' pipeline: MPC space resection on GCPs from the RPC

# %%
scene, report = scene_from_rpc(RPC_FILE, n_gcps=N_GCPS, seed=0)
print(report.summary())

# %% [markdown]
# ## Best-scanline methods on the recovered geometry

# %%
scps = simulate_points(scene, N_SCPS, kind="scp")
scops = simulate_points(scene, 100, kind="scop")
for name in [m for m in METHODS if m in available()]:
    ev = evaluate_method(create(name, scene), scps, scops)
    print(f"{name:11s} RMSE {ev.rmse_px:.2e} px  dr_max {ev.dr_max_px:.2e} px  CE/pt {ev.ce_evals_per_point:.1f}")

# %% [markdown]
# ## The recovered scene against the RPC itself
# Project independent ground points with the RPC and with the scene's rigorous model (`exact`).

# %%
sample = scps.ground[:: max(1, len(scps) // 500)]
lon_s, lat_s, h_s = scene.frame.enu_to_geodetic(sample)
row_rpc, col_rpc = rpc.projection(lon_s, lat_s, h_s)
res = create("exact", scene).ground_to_image(sample)
d = np.hypot(res.row - row_rpc, res.col - col_rpc)
print(f"MPC scene vs RPC on {d.size} points: RMS {np.sqrt(np.mean(d**2)):.3f} px, max {d.max():.3f} px")
assert np.sqrt(np.mean(d**2)) < 1.0

# %% [markdown]
# ## Exercises
# 1. Build the rigorous model of the other Pleiades datastrip
#    (`PHRDIMAP_P1BP--2017030824934340CP.XML`). Is its RPC as faithful? Where on the image is the
#    difference largest?
# 2. Raise the MPC degree of the resection to 3 (`degree=3`). Does the fit to the RPC improve, and
#    why would agile acquisitions need it?
# 3. The raw DIMAP attitude samples are noisy: build the rigorous model with
#    `attitude_smoothing=None` and compare it with the RPC. Is the difference a function of the
#    row (time), of the column, or of both? What does that tell you about its cause?
