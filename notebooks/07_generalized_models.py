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
# # 04 · Generalized models: RFM, the BP-network geometry model, NN-regularised RFM
#
# **What this teaches.** Vendors ship a rational function model (RFM/RPC) fitted to their rigorous
# model on a 3D grid (*terrain-independent*). Yue et al. replace it with a BP network (x, y, Z) → (X, Y);
# Habib et al. regularise an RFM fitted on irregular GCPs with an MLP that first fills a regular grid.
# Here all three are fitted to our rigorous model and judged on independent check points.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
PRESET = "WSU"
N_SCPS = 2000 if SMALL else 100000

# %%

from explorer.evaluate import evaluate_method
from explorer.methods import available, create
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
scps = simulate_points(scene, N_SCPS, kind="scp")
scops = simulate_points(scene, 100, kind="scop")
for name in ["rfm", "bpnn", "nn-rfm"]:
    if name not in available():
        continue
    m = create(name, scene)
    ev = evaluate_method(m, scps, scops if m.needs_fit else None)
    print(f"{name:7s} row RMSE {ev.rmse_px:.2e} px, dr_max {ev.dr_max_px:.2e} px, column RMSE {ev.col_rmse_px:.2e} px")

# %% [markdown]
# ## The papers' protocols
# `explorer.methods.bpnn.compare_bpnn_rfm` and `explorer.methods.nn_rfm.compare_nn_rfm` reproduce the
# comparisons of Yue et al. (Tables 2-6) and Habib et al. (Table 2); `docs/results.md` puts them beside
# the published numbers.

# %%
try:
    from explorer.methods.bpnn import compare_bpnn_rfm

    print(compare_bpnn_rfm(scene, mode="terrain-independent", seed=0))
except ImportError as exc:
    print("bpnn not available:", exc)

# %%
try:
    from explorer.methods.nn_rfm import compare_nn_rfm

    print(compare_nn_rfm(scene, seed=0))
except ImportError as exc:
    print("nn-rfm not available:", exc)

# %% [markdown]
# ## Exercises
# 1. Fit the RFM on a 3D grid with only 2 height layers. What happens at heights outside them?
# 2. Add relief (1000 m) and compare the terrain-dependent and terrain-independent BP networks.
# 3. Why does a cubic RFM fit a smooth pushbroom so well, and what would break it (hint: jitter)?
