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


def bws_evaluations(k, n_rows, final_window=8):
    """CE per point of BWS from its definition, given only k, the row after which x changes sign (notebook 05)."""
    k = np.asarray(k, dtype=np.int64)
    lo, hi = np.full(k.shape, -1), np.full(k.shape, n_rows)
    halvings = np.zeros(k.shape, np.int64)
    while np.any(big := hi - lo + 1 > final_window):
        mid = (lo + hi) // 2
        left = big & (k < mid)
        hi = np.where(left, mid, hi)
        lo = np.where(big & ~left, mid, lo)
        halvings += big
    walk = np.minimum(k + 1, hi - 1) - lo
    return 2 + halvings, walk


def predicted_bws_ce(sc, points, ev):
    """(lowest, highest) mean CE per point the definition allows, and the mean number of halvings.

    A root exactly on a row r (x(r) = 0 up to rounding) may be bracketed as [r-1, r] or [r, r+1], so such a
    point has two possible counts; elsewhere both are the same."""
    rows = points.row[ev.evaluated_index]
    (h1, w1), (h2, w2) = (bws_evaluations(k, sc.n_rows) for k in (np.ceil(rows) - 1, np.floor(rows)))
    a, b = float(np.mean(h1 + w1)), float(np.mean(h2 + w2))
    return min(a, b), max(a, b), float(np.mean(h2))

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
# rates bend $x(t)$. Bisection (BWS) does not look at the shape of $x(t)$: its cost is what the count of
# notebook 05 predicts from the image size and the exact rows alone, on WSU and on `agile` alike (to
# 0.01 CE per point; `agile`'s check points lie exactly on rows, where $x = 0$ up to rounding and the
# count can be one more or one less, so there the measured mean must lie between the two counts). Its CE
# per point may still differ between the two scenes, up or down, because their sizes and the rows of
# their check points differ, not because $x(t)$ bends.

# %%
agile = build_scene("agile")
scps_a = simulate_points(agile, N_SCPS, kind="scp")
for name in ("nr", "cpp", "gdp", "hybrid", "csm-secant", "bws-interp"):
    ev_w = evaluate_method(create(name, scene), scps)
    ev_a = evaluate_method(create(name, agile), scps_a)
    print(f"{name:11s} CE/pt WSU {ev_w.ce_evals_per_point:5.2f} -> agile {ev_a.ce_evals_per_point:5.2f}, "
          f"agile dr_max {ev_a.dr_max_px:.1e} px")
    assert ev_a.dr_max_px < 1e-3
    if name != "bws-interp":  # the methods that model the shape of x(t) pay for its curvature
        assert ev_a.ce_evals_per_point > ev_w.ce_evals_per_point
    else:  # bisection: the count from the exact rows (bws-interp = bws + 1 CE for the column)
        for sc, pts, ev in ((scene, scps, ev_w), (agile, scps_a, ev_a)):
            low, high, _ = predicted_bws_ce(sc, pts, ev)
            print(f"   bws-interp on {sc.name}: {sc.n_rows} rows, predicted {low + 1:.2f} to {high + 1:.2f} CE/pt, "
                  f"measured {ev.ce_evals_per_point:.2f}")
            assert low + 1 - 0.01 <= ev.ce_evals_per_point <= high + 1 + 0.01

# %% [markdown]
# ## Exercise 3: BWS on 8300 rows
# Bisecting $N$ lines down to two adjacent ones takes $\lceil \log_2 N \rceil$ steps: 14 for 8300,
# 12 for 3996. Our BWS starts from the whole image (rows $-1$ to $N$), halves until 8 rows are left and
# walks those (notebook 05): the count from its definition predicts both sizes to 0.01 CE per point.
# Doubling the image adds one halving, not twice the work: the mean number of halvings grows by
# $\log_2(8300/3996) \approx 1.05$ (within 0.5, since halvings are whole numbers).

# %%
long = dataclasses.replace(scene, n_rows=8300)
ce, halvings = {}, {}
for sc in (scene, long):
    pts = simulate_points(sc, N_SCPS, kind="scp")
    ev = evaluate_method(create("bws", sc), pts)
    ce[sc.n_rows] = ev.ce_evals_per_point
    low, high, halvings[sc.n_rows] = predicted_bws_ce(sc, pts, ev)
    print(f"{sc.n_rows} rows: ceil(log2 N) = {int(np.ceil(np.log2(sc.n_rows)))}, BWS {ce[sc.n_rows]:.2f} CE/pt "
          f"(predicted {low:.2f} to {high:.2f}), {halvings[sc.n_rows] - 2:.2f} halvings")
    assert low - 0.01 <= ce[sc.n_rows] <= high + 0.01
growth = halvings[8300] - halvings[scene.n_rows]
print(f"halvings grow by {growth:.2f}; log2(8300/{scene.n_rows}) = {np.log2(8300 / scene.n_rows):.2f}")
assert abs(growth - np.log2(8300 / scene.n_rows)) <= 0.5
