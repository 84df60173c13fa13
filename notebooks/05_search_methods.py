# %% [markdown]
# # 05 · Best scanline search: SS, BWS, interpolation, NR, CPP, GDP, hybrid
#
# **Learning goals.** After this notebook you can
#
# 1. describe how each search method finds the best scanline: sequential search (SS), bisecting
#    window search (BWS), their sub-pixel interpolation (the weighted mean of Ahooei Nezhad et
#    al. 2020), Newton-Raphson (NR), the central perspective plane (CPP), the generic
#    differential (GDP) and the hybrid object-space method;
# 2. predict their cost in collinearity evaluations (CE) per point and their accuracy, and check
#    the prediction (the count of BWS's evaluations from its definition, the interpolation error bound);
# 3. read a method's convergence from its search trace, in a plot and in the 3D view.
#
# **Prerequisites.** Notebooks 01 and 04 (the along-track residual and its derivative).
#
# **Estimated time.** 60 minutes.
#
# All methods share one interface (`explorer.methods.create(name, scene)`, then
# `ground_to_image(points)`) and are measured the same way (`explorer.evaluate.evaluate_method`):
# RMSE and $dr_{max}$ of the row, CE per point, time.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
PRESET = "WSU"
N_SCPS = 500 if SMALL else 20000
N_SS = 100 if SMALL else 2000  # the sequential searches are slow: a subsample
METHODS = ["ss", "bws", "ss-interp", "bws-interp", "nr", "cpp", "gdp", "hybrid", "exact", "csm-secant"]

# %%
import numpy as np
import plotly.graph_objects as go

from explorer.evaluate import evaluate_method
from explorer.methods import available, create
from explorer.notebook import interactive_figure, scene_view
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene(PRESET)
scps = simulate_points(scene, N_SCPS, kind="scp")
methods = [m for m in METHODS if m in available()]
print("methods here:", methods)

# %% [markdown]
# ## Accuracy, cost and time on the same check points

# %%
evals = {}
for name in methods:
    n = N_SS if name.startswith("ss") else None
    evals[name] = ev = evaluate_method(create(name, scene), scps, max_points=n)
    print(f"{name:11s} RMSE {ev.rmse_px:9.2e} px  dr_max {ev.dr_max_px:9.2e} px  CE/pt {ev.ce_evals_per_point:7.1f} "
          f"(max {ev.ce_evals_max:4d})  {ev.locate_s / ev.n_evaluated * 1e6:9.2f} µs/pt on {ev.n_evaluated} pts")

# %%
fig = go.Figure(go.Bar(x=list(evals), y=[e.ce_evals_per_point for e in evals.values()]))
fig.update_layout(title="Collinearity evaluations per point", yaxis_type="log", height=320)
fig

# %% [markdown]
# ## Pixel-level searches: SS and BWS
# SS evaluates $x$ on every line and keeps the line where $|x|$ is smallest: its error is at most
# half a line. BWS brackets the sign change of $x$ and halves the bracket. Bisecting $N$ lines down
# to two adjacent ones would take $\lceil \log_2 N \rceil$ evaluations; our BWS (the default
# `final_window=8`) spends
#
# $$ \mathrm{CE} = 2 + h + w, $$
#
# two for the ends of the window (rows $-1$ and $N$), $h$ halvings until the window holds at most 8
# rows, and a walk of $w$ rows through that last window until $x$ changes sign ($0 \le w \le 6$; it
# depends on where the root falls in the window). The cell counts $h$ and $w$ for every check point
# from its exact row alone, with integer arithmetic, and compares the mean with what BWS reports: they
# must agree to 0.01 CE per point.

# %%
def bws_evaluations(k, n_rows, final_window=8):
    """CE per point of BWS from its definition, given only k, the row after which x changes sign."""
    k = np.asarray(k, dtype=np.int64)
    lo, hi = np.full(k.shape, -1), np.full(k.shape, n_rows)
    halvings = np.zeros(k.shape, np.int64)
    while np.any(big := hi - lo + 1 > final_window):
        mid = (lo + hi) // 2
        left = big & (k < mid)  # the sign change lies in [lo, mid]
        hi = np.where(left, mid, hi)
        lo = np.where(big & ~left, mid, lo)
        halvings += big
    walk = np.minimum(k + 1, hi - 1) - lo  # rows lo+1 ... evaluated until the sign change (hi is known)
    return 2 + halvings, walk


bws_ev = evals["bws"]
exact_rows = scps.row[bws_ev.evaluated_index]
assert np.all(np.abs(exact_rows - np.round(exact_rows)) > 1e-6)  # no root exactly on a row: k is unambiguous
h, w = bws_evaluations(np.floor(exact_rows), scene.n_rows)
predicted = float(np.mean(h + w))
log2n = int(np.ceil(np.log2(scene.n_rows)))
print(f"N = {scene.n_rows} rows: 2 ends + {np.mean(h) - 2:.2f} halvings + {np.mean(w):.2f} walked rows = "
      f"{predicted:.2f} CE predicted; BWS reports {bws_ev.ce_evals_per_point:.2f} (ceil(log2 N) = {log2n})")
assert evals["ss"].dr_max_px <= 0.5 + 1e-9 and evals["bws"].dr_max_px <= 0.5 + 1e-9
assert abs(predicted - bws_ev.ce_evals_per_point) <= 0.01
assert np.all((w >= 0) & (w <= 6))

# %% [markdown]
# ## Sub-pixel interpolation (Ahooei Nezhad et al. 2020, Eq. 4)
# Between the two lines $t_1, t_2$ where $x$ changes sign, take the weighted mean
#
# $$ t = \frac{t_1/|x_1| + t_2/|x_2|}{1/|x_1| + 1/|x_2|}. $$
#
# With opposite signs this is exactly the zero of the straight line through $(t_1, x_1)$ and
# $(t_2, x_2)$, $t = t_1 - x_1 (t_2 - t_1)/(x_2 - x_1)$. Its error comes from the curvature of
# $x(t)$ only: with $s = dx/dr$ and $a = d^2x/dr^2$ (per row), it is at most $|a| / (8 |s|)$ rows.

# %%
rng = np.random.default_rng(0)
t1, x1 = rng.normal(size=1000), rng.uniform(0.01, 1, 1000)
t2, x2 = t1 + 1, -rng.uniform(0.01, 1, 1000)
weighted = (t1 / np.abs(x1) + t2 / np.abs(x2)) / (1 / np.abs(x1) + 1 / np.abs(x2))
secant = t1 - x1 * (t2 - t1) / (x2 - x1)
assert np.allclose(weighted, secant, rtol=0, atol=1e-12)

ev = evals["bws-interp"]
sub = scps.subset(ev.evaluated_index)
r = sub.row
t_r = scene.scanline_time
xm, x0, xp = (scene.along_track_residual(sub.ground, t_r(r + k)) / scene.pixel_size_m for k in (-1.0, 0.0, 1.0))
slope, curvature = (xp - xm) / 2, xp - 2 * x0 + xm
bound = np.abs(curvature) / (8 * np.abs(slope))
print(f"interpolation error max {np.nanmax(np.abs(ev.residual_row)):.2e} px, bound max {bound.max():.2e} px")
assert np.all(np.abs(ev.residual_row) <= bound + 1e-10)
assert evals["bws-interp"].ce_evals_per_point == evals["bws"].ce_evals_per_point + 1

# %% [markdown]
# ## How they converge: the rows visited for one point
# `ground_to_image(points, trace=True)` records the candidate row per iteration. NR and CPP
# converge quadratically from the image centre; BWS halves the window each step.

# %%
DEFAULT_INDEX = len(scps) // 3


def convergence(index=DEFAULT_INDEX, methods_shown=("bws", "nr", "cpp", "gdp", "hybrid", "csm-secant")):
    point = scps.ground[index][None, :]
    exact_row = scps.row[index]
    fig = go.Figure()
    for name in methods_shown:
        if name not in methods:
            continue
        res = create(name, scene).ground_to_image(point, trace=True)
        if res.trace:
            path = np.array([float(np.asarray(a).ravel()[0]) for a in res.trace])
            path = path[np.isfinite(path)]
            fig.add_scatter(y=np.abs(path - exact_row) + 1e-12, mode="lines+markers", name=name)
    return fig.update_layout(title=f"|row - exact row| per iteration, SCP {index} (row {exact_row:.2f})",
                             yaxis_type="log", xaxis_title="iteration", height=350)


interactive_figure(convergence, index=(0, len(scps) - 1, 1))

# %% [markdown]
# ## The search in 3D
# The scanlines BWS visited for one point, first (yellow) to last (purple), around its ray.

# %%
scene_view(scene, point=(0.85 * scene.n_rows, 0.3 * scene.n_columns), method="bws")

# %% [markdown]
# ## Exercises
# 1. SS and BWS are "pixel-level": their $dr_{max}$ is at most half a pixel. Which line do they
#    return, the nearest one or the one before the sign change? Check on a few points with the
#    residuals.
# 2. Run on `agile` (large attitude rates). Which methods need more iterations, and why (think of
#    what each assumes about $x(t)$)?
# 3. How many CE does BWS need for an image of 8300 rows? Compare with $\log_2 8300$ and with what
#    `create("bws", scene)` reports on a scene of that size.
