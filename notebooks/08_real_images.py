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
# # 05 · Real images: from a vendor RPC file to best-scanline methods
#
# **What this teaches.** The papers built their test scenes from real images: GCPs derived from the
# image's RPC file, heights from a DEM, an MPC space resection (per-line exterior orientation as
# polynomials of time), then simulated SCOPs/SCPs. You will run that pipeline on a real Pleiades RPC
# (CNES shareloc test data) with its DEM, look at the resection residuals, and run the methods on the
# recovered scene.
#
# RPC pixel conventions differ (DIMAP is 1-based); readers convert everything to 0-based pixel centres
# (`docs/rpc.md`, `docs/conventions.md`).

# %% tags=["parameters"]
import os
from pathlib import Path

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
ROOT = Path.cwd().parent
RPC_FILE = ROOT / "tests" / "data" / "rpc" / "rpc_PLEIADES.xml"
N_GCPS = 49 if SMALL else 400
N_SCPS = 2000 if SMALL else 200000
METHODS = ["nr", "bws-interp", "lrm", "prm", "exact"]

# %%
import numpy as np

from explorer.evaluate import evaluate_method
from explorer.methods import available, create
from explorer.points import simulate_points
from explorer.real.from_rpc import scene_from_rpc
from explorer.rpc import read_rpc

rpc = read_rpc(RPC_FILE)
print(type(rpc).__name__, rpc.source_format, "image size", rpc.image_size)

# %% [markdown]
# ## MPC space resection on GCPs from the RPC

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
lon, lat, h = scene.frame.enu_to_geodetic(sample)
row_rpc, col_rpc = rpc.projection(lon, lat, h)
res = create("exact" if "exact" in available() else "nr", scene).ground_to_image(sample)
d = np.hypot(res.row - row_rpc, res.col - col_rpc)
print(f"scene vs RPC on {d.size} points: RMS {np.sqrt(np.mean(d**2)):.3f} px, max {d.max():.3f} px")

# %% [markdown]
# ## Exercises
# 1. Use the Pleiades DIMAP file with its DEM (`assets/dem/`): how do the GCP residuals change with terrain?
# 2. Raise the MPC degree to 3. Why do agile acquisitions need it?
# 3. Run `./run.sh rpc info tests/data/rpc/rpc_WV2.xml` and compare the validity domain with the scene footprint.
