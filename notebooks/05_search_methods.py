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
# # 02 · Search methods: how each one finds the best scanline
#
# **What this teaches.** Sequential search (SS) tries every line; the bisecting window search (BWS)
# halves the window by the sign of x; their interpolated versions add one weighted mean
# `t = (t1/|x1| + t2/|x2|) / (1/|x1| + 1/|x2|)`; Newton-Raphson (NR) follows the derivative; CPP, GDP and
# the hybrid method work in object space. All methods share one interface (`explorer.methods.create`)
# and are measured the same way: RMSE and dr_max of the row, collinearity evaluations (CE) per point, time.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
PRESET = "WSU"
N_SCPS = 500 if SMALL else 20000
METHODS = ["ss", "bws", "ss-interp", "bws-interp", "nr", "cpp", "gdp", "hybrid", "exact", "csm-secant"]

# %%
import numpy as np
import plotly.graph_objects as go

from explorer.evaluate import evaluate_method
from explorer.methods import available, create
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
scps = simulate_points(scene, N_SCPS, kind="scp")
methods = [m for m in METHODS if m in available()]
print("methods here:", methods)

# %% [markdown]
# ## How they converge: the rows visited for one point
# `ground_to_image(points, trace=True)` records the candidate row per iteration.

# %%
point = scps.ground[len(scps) // 3][None, :]
exact_row = scps.row[len(scps) // 3]
fig = go.Figure()
for name in methods:
    res = create(name, scene).ground_to_image(point, trace=True)
    if res.trace:
        path = np.array([float(r[0]) for r in res.trace])
        path = path[np.isfinite(path)]
        fig.add_scatter(y=np.abs(path - exact_row) + 1e-12, mode="lines+markers", name=name)
fig.update_layout(title="|row - exact row| per iteration", yaxis_type="log", xaxis_title="iteration")
fig

# %% [markdown]
# ## Accuracy, cost and time on the same check points

# %%
rows = []
for name in methods:
    ev = evaluate_method(create(name, scene), scps, max_points=min(len(scps), 2000 if name == "ss" else N_SCPS))
    rows.append(ev.summary())
    print(f"{name:11s} RMSE {ev.rmse_px:9.2e} px  dr_max {ev.dr_max_px:9.2e} px  "
          f"CE/pt {ev.ce_evals_per_point:7.1f}  {ev.locate_s / ev.n_evaluated * 1e6:8.2f} us/pt")

# %%
fig = go.Figure(go.Bar(x=[r["method"] for r in rows], y=[r["ce_evals_per_point"] for r in rows]))
fig.update_layout(title="Collinearity evaluations per point", yaxis_type="log")
fig

# %% [markdown]
# ## Exercises
# 1. SS and BWS are "pixel-level": their dr_max is at most one pixel. Which line do they return, the
#    nearest or the one before the sign change? Check with the residuals.
# 2. Run on `agile`. Which methods need more iterations, and why (think of what each assumes about x(t))?
# 3. Count: how many CE does BWS need for an image of 8300 rows? Compare with log2(8300).
