# %% [markdown]
# # 10 · Solutions: reproducing the papers
#
# Worked answers to the exercises of notebook 10, each checked against an independent value (the
# papers' tables, closed forms, a direct timing).

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
N_SCPS = 5000 if SMALL else 200_000

# %%
import time

from explorer import paper_tables  # the published tables, as data
from explorer.evaluate import evaluate_method
from explorer.methods import create
from explorer.points import simulate_points
from explorer.presets import build_scene

mlp4 = {row[0]: row for row in paper_tables.MLP_TABLE4["datasets"]["ISB"]}

# %% [markdown]
# ## Exercise 1: the NR / MLP time ratio
# The paper: NR 511.9 s, MLP 3.29 s for five million SCPs on ISB, a ratio of about 156. Ours on the
# same image (per point, so the size does not matter): NR runs a compiled, vectorised Newton loop of
# ~4 CE per point; the MLP is one small matrix product per point. The ratio depends on how each is
# implemented far more than on the CE count: the paper's NR is a per-point Python-level loop.

# %%
isb = build_scene("ISB")
scps = simulate_points(isb, N_SCPS, kind="scp")
scops = simulate_points(isb, 100, kind="scop")
ev_nr = evaluate_method(create("nr", isb), scps)
ev_mlp = evaluate_method(create("mlp", isb), scps, scops)
paper_ratio = mlp4["nr"][2] / mlp4["mlp"][2]
ours = (ev_nr.locate_s / ev_nr.n_evaluated) / (ev_mlp.locate_s / ev_mlp.n_evaluated)
print(f"paper NR / MLP time ratio {paper_ratio:.0f}; ours {ours:.1f} (NR {ev_nr.ce_evals_per_point:.2f} CE per point)")
assert abs(paper_ratio - 511.919 / 3.29) < 1e-9
bss = {row[0]: row for row in paper_tables.BSS2020_TABLE2["rows"]}
assert ev_nr.ce_evals_max <= bss["nr"][2]  # the 2020 paper's NR needs at most 4 CE per point (Table 2)

# %% [markdown]
# ## Exercise 2: which attitude rate makes the LRM exact on WSU?
# None: even without attitude rates the orbit's curvature (and the Earth's rotation) keep $t(P)$
# non-affine: about 5e-3 px (asserted between 1e-3 and 1e-2 px below). Only a straight orbit at
# constant attitude — the `linear` preset — gives the paper's 1e-9 px: the papers' simulation must
# have used such a model.

# %%
lrm = {}
for label, sc in (("WSU, rate x0", build_scene("WSU", attitude_rate_scale=0.0)), ("linear", build_scene("linear"))):
    pts = simulate_points(sc, 2000, kind="scp")
    lrm[label] = evaluate_method(create("lrm", sc), pts, simulate_points(sc, 30, kind="scop")).rmse_px
    print(f"{label:13s}: lrm RMSE {lrm[label]:.1e} px")
paper_wsu = [row[3] for row in paper_tables.LRM_TABLE3["rows"] if row[1] == "WSU"]
assert lrm["WSU, rate x0"] > 1e-8 > max(paper_wsu) and lrm["linear"] < max(paper_wsu)
assert 1e-3 < lrm["WSU, rate x0"] < 1e-2  # the "about 5e-3 px" of the text

# %% [markdown]
# ## Exercise 3: our BWS on five million points
# Estimate from a small run and compare with a direct timing on a larger sample (timings on a shared
# machine vary; the work per point, in CE, does not).

# %%
wsu = build_scene("WSU")
small = simulate_points(wsu, 2000, kind="scp")
large = simulate_points(wsu, N_SCPS, kind="scp")
m = create("bws", wsu)
m.ground_to_image(small.ground[:100])  # warm-up (compiled kernels)
t0 = time.perf_counter()
m.ground_to_image(small.ground)
per_point = (time.perf_counter() - t0) / len(small)
t0 = time.perf_counter()
m.ground_to_image(large.ground)
per_point_large = (time.perf_counter() - t0) / len(large)
print(f"estimate for 5e6 points: {per_point * 5e6:.1f} s (from {len(large)} points: {per_point_large * 5e6:.1f} s); "
      f"paper: {mlp4['bws'][2]:.0f} s")
# the work per point, and so the extrapolation, does not depend on the sample: same CE per point
ce_small = evaluate_method(m, small).ce_evals_per_point
ce_large = evaluate_method(m, large).ce_evals_per_point
print(f"CE per point: {ce_small:.2f} on {len(small)} points, {ce_large:.2f} on {len(large)}")
assert abs(ce_small - ce_large) < 0.5
