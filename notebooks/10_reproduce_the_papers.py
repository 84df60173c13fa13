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
# # 06 · Reproduce the papers' comparisons
#
# **What this teaches.** The papers compare best-scanline methods on ten images with 5,000,000 check
# points each. This notebook runs the same protocol through `explorer.bench` (the engine of
# `pushbroom bench`) at a size that runs anywhere, with a switch for the full protocol, and prints our
# numbers beside the published ones. The full discussion (verdicts, where we disagree and why) is in
# `docs/results.md`.

# %% tags=["parameters"]
import os

SMALL = os.environ.get("PUSHBROOM_NB_SMALL", "0") == "1"
FULL_PROTOCOL = False  # True: 5,000,000 SCPs per image, all ten images (hours for the slow methods)
PRESETS = ["WSU", "linear"] if SMALL else ["ISB", "PMA", "PAU", "QII", "SJB", "SAN", "SCB", "WBU", "WSA", "WSU"]
METHODS = ["nr", "bws", "lrm", "mlp"]
SCOPS = [10, 30, 50, 100]
N_SCPS = 5_000_000 if FULL_PROTOCOL else (2000 if SMALL else 200_000)

# %%
from explorer.bench import run_bench
from explorer.methods import available

methods = [m for m in METHODS if m in available()]
report = run_bench(presets=PRESETS, methods=methods, scops=SCOPS, n_scps=N_SCPS, seed=0, progress=False)
def num(v):
    return "n/a" if v is None else f"{v:.2e}"


for r in report.runs:
    print(f"{r['preset']:7s} {r['method']:6s} SCOPs {r['n_scops']:4d}: RMSE {num(r['rmse_px'])} px "
          f"dr_max {num(r['dr_max_px'])} px  locate {num(r['locate_s'])} s on {r['n_evaluated']} points")

# %% [markdown]
# ## The published numbers
# `benchmarks/paper_tables.py` holds the papers' tables as data; `benchmarks/reproduce_papers.py`
# writes `docs/results.md` with both side by side.

# %%
import sys
from pathlib import Path

sys.path.insert(0, str(Path.cwd().parent / "benchmarks"))
try:
    import paper_tables

    print([name for name in dir(paper_tables) if name.isupper()])
except ImportError as exc:
    print("paper tables not found:", exc)

# %% [markdown]
# ## Exercises
# 1. Set `FULL_PROTOCOL = True` for one image and compare the timing ratio NR / MLP with the paper's.
# 2. Which of the paper's claims depend on the orbit model? Try the `linear` preset for LRM.
