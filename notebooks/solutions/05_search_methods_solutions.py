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
# # 05 · Solutions: best scanline search
#
# Worked answers to the exercises of notebook 05, each checked against an independent value.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_SCPS = 300 if SMALL else 5000

# %%
import dataclasses

import numpy as np

from explorer.evaluate import evaluate_method
from explorer.methods import create
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene("WSU")
scps = simulate_points(scene, N_SCPS, kind="scp")

# %% [markdown]
# ## Exercise 1: which line do SS and BWS return?
# The nearest one: the returned row is the exact row rounded, and $|x|$ there is no larger than on
# the neighbouring lines (brute force).

# %%
sub = scps.sample(min(len(scps), 100), seed=1)
for name in ("ss", "bws"):
    rows = create(name, scene).ground_to_image(sub.ground).row
    assert np.array_equal(rows, np.round(rows)) and np.all(np.abs(rows - sub.row) <= 0.5 + 1e-9), name
    x = {k: np.abs(scene.along_track_residual(sub.ground, scene.scanline_time(rows + k))) for k in (-1, 0, 1)}
    assert np.all(x[0] <= x[-1] + 1e-12) and np.all(x[0] <= x[1] + 1e-12), name
    ties = np.abs(sub.row - np.floor(sub.row) - 0.5) < 1e-9
    print(f"{name}: nearest line for all {len(sub)} points ({ties.sum()} exact ties at .5 go to the lower line)")

# %% [markdown]
# ## Exercise 2: `agile`
# Everything still converges to the exact rows (checked against the SCPs' exact rows), but the
# methods that model $x(t)$ as a straight line or use one derivative need more steps: the attitude
# rates bend $x(t)$. Bisection (BWS) does not care about the shape of $x(t)$, only about the number of
# rows, so its cost does not grow.

# %%
agile = build_scene("agile")
scps_a = simulate_points(agile, N_SCPS, kind="scp")
for name in ("nr", "cpp", "gdp", "hybrid", "csm-secant", "bws-interp"):
    ev_w = evaluate_method(create(name, scene), scps)
    ev_a = evaluate_method(create(name, agile), scps_a)
    print(f"{name:11s} CE/pt WSU {ev_w.ce_evals_per_point:5.2f} -> agile {ev_a.ce_evals_per_point:5.2f}, "
          f"agile dr_max {ev_a.dr_max_px:.1e} px")
    assert ev_a.dr_max_px < 1e-3
    if name != "bws-interp":  # bisection's cost depends on the number of rows only, not on the shape of x(t)
        assert ev_a.ce_evals_per_point > ev_w.ce_evals_per_point

# %% [markdown]
# ## Exercise 3: BWS on 8300 rows
# Halving a window of $N$ lines down to one takes $\lceil \log_2 N \rceil$ steps: 14 for 8300, 12 for
# 3996; our BWS starts from a predicted window, so it spends a little more on average but grows by at
# most $\log_2(8300/3996) \approx 1.05$ evaluations when the image doubles.

# %%
long = dataclasses.replace(scene, n_rows=8300)
ce = {}
for sc in (scene, long):
    ce[sc.n_rows] = evaluate_method(create("bws", sc), simulate_points(sc, N_SCPS, kind="scp")).ce_evals_per_point
print({n: round(v, 2) for n, v in ce.items()}, "log2(8300) =", round(np.log2(8300), 2))
assert 0 <= ce[8300] - ce[scene.n_rows] <= np.log2(8300 / scene.n_rows) + 0.2
