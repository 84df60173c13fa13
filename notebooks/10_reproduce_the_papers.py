# %% [markdown]
# # 10 · Reproducing the papers
#
# **Learning goals.** After this notebook you can
#
# 1. run the papers' protocol (ten images, SCOPs at 10/30/50/100, millions of SCPs, RMSE Eq. 4 and
#    $dr_{max}$ Eq. 5) through `explorer.bench`, the engine of `pushbroom bench`;
# 2. put our numbers beside the published tables and explain the differences that come from
#    *definitions* (which scanline a pixel-level search returns) and from the *orbit model* (why the
#    LRM paper reports 1e-9 px on every image);
# 3. judge which of the papers' claims survive an independent implementation.
#
# **Prerequisites.** Notebooks 05 and 06.
#
# **Estimated time.** 45 minutes (the full protocol takes hours: `FULL_PROTOCOL = True`).
#
# The full discussion (verdicts, where we disagree and why) is `docs/results.md`; the published
# numbers are transcribed as data in `explorer/paper_tables.py`.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
FULL_PROTOCOL = False  # True: 5,000,000 SCPs per image, the ten images and `linear` (hours for the slow methods)
PRESETS = ["WSU", "linear"] if SMALL else ["ISB", "PMA", "PAU", "QII", "SJB", "SAN", "SCB", "WBU", "WSA", "WSU",
                                           "linear"]
METHODS = ["nr", "bws", "lrm", "mlp"]
SCOPS = [10, 30, 50, 100]
N_SCPS = 5_000_000 if FULL_PROTOCOL else (2000 if SMALL else 200_000)

# %%
import numpy as np
import plotly.graph_objects as go

from explorer import paper_tables  # the published tables, as data
from explorer.bench import run_bench
from explorer.methods import available
from explorer.notebook import interactive_figure
from explorer.points import simulate_points
from explorer.presets import build_scene

methods = [m for m in METHODS if m in available()]
report = run_bench(presets=PRESETS, methods=methods, scops=SCOPS, n_scps=N_SCPS, seed=0, progress=False)


def num(v):
    return "n/a" if v is None else f"{v:.2e}"


for r in report.runs:
    print(f"{r['preset']:7s} {r['method']:6s} SCOPs {r['n_scops']:4d}: RMSE {num(r['rmse_px'])} px "
          f"dr_max {num(r['dr_max_px'])} px  locate {num(r['locate_s'])} s on {r['n_evaluated']} points")

# %% [markdown]
# ## A definition, not a bug: which line does BWS return?
# A pixel-level search returns an integer line. If it is the **nearest** line, the error is uniform
# on $[-\tfrac12, \tfrac12]$ and
#
# $$ \mathrm{RMSE} = \sqrt{\int_{-1/2}^{1/2} u^2 du} = \frac{1}{\sqrt{12}} \approx 0.289, \qquad dr_{max} = 0.5; $$
#
# if it is the line **before the sign change** (the floor), the error is uniform on $[0, 1)$ and
# $\mathrm{RMSE} = 1/\sqrt{3} \approx 0.577$, $dr_{max} \to 1$. The 2020 paper prints 0.30 for BWS
# (Table 2); the MLP paper prints 0.57 with $dr_{max}$ 1.0 (Table 4): the two papers use the two
# definitions.

# %%
bss = {row[0]: row for row in paper_tables.BSS2020_TABLE2["rows"]}
mlp4 = {row[0]: row for row in paper_tables.MLP_TABLE4["datasets"]["ISB"]}
print("2020 paper, BWS RMSE:", bss["bws"][3], " MLP paper, BWS RMSE:", mlp4["bws"][1], "dr_max", mlp4["bws"][3])
assert abs(bss["bws"][3] - 1 / np.sqrt(12)) < 0.015
assert abs(mlp4["bws"][1] - 1 / np.sqrt(3)) < 0.01 and mlp4["bws"][3] == 1.0

scene = build_scene("WSU")
scps = simulate_points(scene, N_SCPS, kind="scp")
for name, rows in (("nearest", np.rint(scps.row)), ("floor", np.floor(scps.row))):
    e = rows - scps.row
    print(f"{name:8s}: RMSE {np.sqrt(np.mean(e**2)):.4f} px, dr_max {np.abs(e).max():.3f} px")
ours_bws = [r for r in report.runs if r["preset"] == "WSU" and r["method"] == "bws"][0]
print(f"our bws (nearest line) on WSU: RMSE {ours_bws['rmse_px']:.4f} px")
assert abs(ours_bws["rmse_px"] - 1 / np.sqrt(12)) < 0.02

# %% [markdown]
# ## The cost of the collinearity searches (2020 paper, Table 2)
# The paper's maximum CE per point: NR 4, the hybrid object-space method 3.

# %%
from explorer.evaluate import evaluate_method  # noqa: E402
from explorer.methods import create  # noqa: E402

for name in ("nr", "hybrid"):
    ev = evaluate_method(create(name, scene), scps)
    print(f"{name:7s}: max CE per point {ev.ce_evals_max} (paper: {bss[name][2]}), RMSE {ev.rmse_px:.1e} px")
    assert ev.ce_evals_max <= bss[name][2]

# %% [markdown]
# ## The orbit model decides the LRM's accuracy
# The LRM paper (Table 3) reports RMSE between 1e-10 and 5e-9 px on all ten images. Notebook 06
# showed the LRM is exact only for a straight orbit at constant attitude; on our Keplerian presets
# with attitude rates it leaves between a few thousandths and a few hundredths of a pixel (asserted:
# 0.001 to 0.1 px on every such preset run here), while our `linear` preset (straight orbit, constant
# attitude) stays at or below the paper's largest WSU value.

# %%
lrm_paper = [row for row in paper_tables.LRM_TABLE3["rows"] if row[1] == "WSU"]
print("paper, WSU (SDWV):", [(n, rmse) for _, _, n, rmse, _, _ in lrm_paper])
for preset in PRESETS:
    ours = [(r["n_scops"], r["rmse_px"]) for r in report.runs if r["preset"] == preset and r["method"] == "lrm"]
    print(f"ours, {preset}:", [(n, f"{v:.1e}") for n, v in ours])
ours_linear = [r["rmse_px"] for r in report.runs if r["preset"] == "linear" and r["method"] == "lrm"]
assert ours_linear and max(ours_linear) <= max(rmse for *_, rmse, _, _ in lrm_paper)
keplerian = [r["rmse_px"] for r in report.runs if r["preset"] != "linear" and r["method"] == "lrm"]
assert keplerian and all(1e-3 <= v <= 0.1 for v in keplerian)

# %% [markdown]
# ## Interactive: our RMSE beside the paper's, per method

# %%
def compare(preset=PRESETS[0], method="lrm"):
    rr = [r for r in report.runs if r["preset"] == preset and r["method"] == method]
    fig = go.Figure(go.Scatter(x=[r["n_scops"] or 1 for r in rr], y=[max(r["rmse_px"] or 0, 1e-12) for r in rr],
                               mode="lines+markers", name=f"ours ({preset})"))
    if method == "lrm":
        pr = [row for row in paper_tables.LRM_TABLE3["rows"] if row[1] == preset]
        if pr:
            fig.add_scatter(x=[row[2] for row in pr], y=[row[3] for row in pr], mode="lines+markers",
                            name="LRM paper, Table 3")
    elif preset == "ISB" and method in mlp4:
        fig.add_hline(y=mlp4[method][1], line_dash="dot", annotation_text="MLP paper, Table 4")
    return fig.update_layout(xaxis_type="log", yaxis_type="log", xaxis_title="SCOPs", yaxis_title="RMSE (px)",
                             height=350, title=f"{method} on {preset}")


interactive_figure(compare, preset=PRESETS, method=methods)

# %% [markdown]
# ## Exercises
# 1. Set `FULL_PROTOCOL = True` for one image and compare the timing ratio NR / MLP with the
#    paper's (Table 4). Why can the ratio differ by an order of magnitude between implementations?
# 2. Which of the papers' claims depend on the orbit model? Find the `attitude_rate_scale` at which
#    the LRM on WSU falls below 1e-8 px.
# 3. The MLP paper's BWS needs "1490 s for five million points". Estimate our BWS time for five
#    million points from the benchmark above and explain the ratio (CE per point, vectorisation).
