"""Reproduce the papers' tables with ``explorer.bench`` and write ``docs/results.md``.

Usage::

    python benchmarks/reproduce_papers.py                  # the papers' protocol: 5,000,000 SCPs per image
    python benchmarks/reproduce_papers.py --quick          # a couple of minutes (3 presets, 20,000 SCPs)
    python benchmarks/reproduce_papers.py --scps 200000    # any size in between
    python benchmarks/reproduce_papers.py --json runs.json # also keep every run record

Every number of "ours" comes from :func:`explorer.bench.run_bench` / :func:`explorer.bench.bench_scene`, i.e. the
method registry and :func:`explorer.evaluate.evaluate_method`; the papers' numbers come from
``explorer/paper_tables.py``.  Methods missing from the registry when this runs are reported as such.
"""

from __future__ import annotations

import argparse
import copy
import datetime as _dt
import json
import math
import os
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from explorer import paper_tables as pt  # noqa: E402
from explorer.bench import bench_scene, fmt  # noqa: E402
from explorer.methods import available, registry  # noqa: E402
from explorer.presets import build_scene, preset_ids, preset_spec  # noqa: E402

PAPER_PRESETS = [p for p in preset_ids() if p not in ("linear", "agile")]
SCOP_COUNTS = (10, 30, 50, 100)


# ------------------------------------------------------------------------------------------------ helpers
class Runner:
    """Runs benchmarks, keeps every record, and knows which methods exist."""

    def __init__(self, n_scps: int, max_points_slow: int, seed: int, progress: bool) -> None:
        self.n_scps = n_scps
        self.max_points_slow = max_points_slow
        self.seed = seed
        self.progress = progress
        self.records: list[dict] = []
        self.verdicts: list[tuple[str, str, str]] = []  # (what, verdict, why)
        self.methods = set(available())
        self._scenes: dict[tuple, object] = {}

    def verdict(self, what: str, verdict: str, why: str) -> None:
        self.verdicts.append((what, verdict, why))

    def has(self, name: str) -> bool:
        return name in self.methods

    def scene(self, preset: str, **kw):
        key = (preset, tuple(sorted(kw.items())))
        if key not in self._scenes:
            self._scenes[key] = build_scene(preset, **kw)
        return self._scenes[key]

    def run(self, scene, label: str, methods, scops=SCOP_COUNTS, *, n_scps: int | None = None, params=None,
            layers: int = 1, relief_m: float = 0.0, experiment: str = "", variant: str = "") -> list[dict]:
        methods = [m for m in methods if self.has(m)]
        if not methods:
            return []
        t0 = time.perf_counter()
        res = bench_scene(
            scene, label, methods, list(scops), int(n_scps or self.n_scps), seed=self.seed, relief_m=relief_m,
            max_points_slow=self.max_points_slow, method_params=params or {}, layers=layers,
        )
        for r in res.runs:
            r["experiment"] = experiment
            r["variant"] = variant
        self.records.extend(res.runs)
        if self.progress:
            done = ", ".join(f"{r['method']}{'/' + str(r['n_scops']) if r['n_scops'] else ''}" for r in res.runs)
            print(f"  [{time.perf_counter() - t0:6.1f} s] {experiment} {label} {variant}: {done}", file=sys.stderr)
        return res.runs


def aligned_presets(presets, n_scps: int) -> dict[str, float]:
    """Presets whose SCP grid puts every SCP at the same fractional row -> that rounding error (px).

    The SCP grid rows are ``(i + 0.5) rows / g - 0.5``; when ``rows / g`` is an integer every SCP has the same
    fractional row (0.5 when it is even, 0 when odd), so a pixel-level method's error is that constant, not
    the uniform rounding error (RMSE 1/sqrt(12)) of a generic grid.
    """
    from explorer.points import grid_shape_for

    out = {}
    for p in presets:
        spec = preset_spec(p)
        g, _ = grid_shape_for(int(n_scps), int(spec["rows"]), int(spec["columns"]))
        rows = (np.arange(g) + 0.5) * spec["rows"] / g - 0.5
        frac = rows - np.round(rows)
        if np.ptp(frac) < 1e-9:
            out[p] = float(abs(frac[0]))
    return out


def aligned_note(presets, n_scps: int) -> str:
    al = aligned_presets(presets, n_scps)
    if not al:
        return ""
    return ("\n_Grid caveat: with " + f"{n_scps:,}" + " SCPs the SCP grid of " + ", ".join(al) + " has an integer row "
            "spacing, so all its SCPs share one fractional row and a pixel-level method's error there is the "
            "constant " + ", ".join(f"{v:g}" for v in sorted(set(al.values()))) + " px, not a uniform rounding "
            "error; those presets are left out of the pixel-level ranges below (another SCP count avoids it)._\n")


def find(runs: list[dict], **kw) -> dict | None:
    for r in runs:
        if all(r.get(k) == v for k, v in kw.items()):
            return r
    return None


def total_s(r: dict | None) -> float | None:
    """Fit time + locate time scaled to all the SCPs (comparable to the papers' times)."""
    if r is None or r.get("locate_s_full_est") is None:
        return None
    return (r.get("fit_s") or 0.0) + r["locate_s_full_est"]


def md_table(headers: list[str], rows: list[list]) -> str:
    def cell(v):
        if isinstance(v, str):
            return v
        return fmt(v)

    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    out += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(out)


def ours(r: dict | None, key: str):
    """A run's metric for a table cell: 'n/a' (not run), 'error', or why there is no value."""
    if r is None:
        return "n/a"
    if r.get("error"):
        return "error"
    v = r.get(key)
    if v is None and key in ("rmse_px", "dr_max_px", "col_rmse_px") and not r.get("valid_frac"):
        return refusal(r)
    return v


def refusal(r: dict) -> str:
    """Why a run has no valid point (a learned method that refused its own fit, say so with its numbers)."""
    m = re.search(r"validation RMSE ([0-9.eE+-]+) px", " ".join(r.get("warnings") or []))
    if r.get("fit_converged") is False:
        return f"fit refused (val. {m.group(1)} px)" if m else "fit refused"
    return "no valid point"


def pair(r: dict | None) -> str:
    """'RMSE / dr_max' cell."""
    if r is None:
        return "n/a"
    if r.get("error"):
        return "error"
    if r.get("rmse_px") is None:
        return refusal(r)
    return f"{fmt(r['rmse_px'])} / {fmt(r['dr_max_px'])}"


def rng_str(values) -> str:
    v = [x for x in values if x is not None and isinstance(x, int | float) and math.isfinite(x)]
    if not v:
        return "n/a"
    lo, hi = min(v), max(v)
    return fmt(lo) if lo == hi else f"{fmt(lo)} - {fmt(hi)}"


def missing_note(runner: Runner, names) -> str:
    miss = [n for n in names if not runner.has(n)]
    return f"\n_Not in the registry when this was generated: {', '.join(miss)}._\n" if miss else ""


# ------------------------------------------------------------------------------------------------ sections
def section_lrm(runner: Runner, presets: list[str]) -> str:
    """LRM paper Table 3 (and PRM / MLP at the same SCOP counts)."""
    runs = []
    for p in presets:
        runs += runner.run(runner.scene(p), p, ["lrm", "prm", "mlp"], SCOP_COUNTS, experiment="lrm_table3")
    t = pt.LRM_TABLE3
    rows = []
    for image, preset, k, rmse, time_s, drmax in t["rows"]:
        if preset not in presets:
            continue
        r = find(runs, preset=preset, method="lrm", n_scops=k)
        rq = find(runs, preset=preset, method="prm", n_scops=k)
        rows.append([f"{preset} ({image})", k, rmse, ours(r, "rmse_px"), drmax, ours(r, "dr_max_px"), time_s,
                     total_s(r) if r else "n/a", ours(rq, "rmse_px")])
    ours_lrm = [r["rmse_px"] for r in runs if r["method"] == "lrm" and not r.get("error")]
    paper_lrm = [row[3] for row in t["rows"] if row[1] in presets]
    if ours_lrm:
        reached = max(ours_lrm) < 1e-7
        verdict = (
            f"**Verdict: {'reproduced' if reached else 'not reproduced'}.** The paper prints LRM RMSEs of "
            f"{rng_str(paper_lrm)} px on the ten images; ours are {rng_str(ours_lrm)} px on the same ten "
            "(simulated) images. "
        )
        runner.verdict("LRM paper Table 3 (LRM, ten images)", "reproduced" if reached else "not reproduced",
                       f"ours {rng_str(ours_lrm)} px vs the paper's {rng_str(paper_lrm)} px: on a curved orbit with "
                       "attitude rates the row is not affine in (X, Y); sub-pixel all the same")
        if not reached:
            verdict += (
                "Our presets fly a curved Keplerian orbit with the attitude following the orbit plus body rates, as "
                "real MPC parameters do; the best scanline is then not an affine function of (X, Y) and an affine "
                "fit leaves a systematic error of order 0.01 px (sub-pixel, but seven orders above 1e-9). "
                "The LRM reaches 1e-9 px only under a straight orbit at constant attitude (next section); the paper's "
                "simulation must have been of that kind in effect (e.g. EOPs held constant or linear in time), though "
                "the paper does not say so. The PRM (degree 2) removes most "
                "of the residual, as the last column shows."
            )
    else:
        verdict = "**Verdict: not run** (lrm is not in the registry)."
    mlp_rows = []
    for p in presets:
        cells = [p]
        for k in SCOP_COUNTS:
            cells.append(pair(find(runs, preset=p, method="mlp", n_scops=k)))
        mlp_rows.append(cells)
    out = [
        "## LRM paper, Table 3: LRM for 10 / 30 / 50 / 100 SCOPs",
        "",
        f"Source: {pt.PAPERS['lrm']['cite']}, {t['table']} ({t['page']}). Protocol: SCOPs and SCPs are regular "
        "image grids mapped to the ground at the mean height; the LRM fits row = a0 + a1 X + a2 Y by least "
        "squares. Times: the paper's are for 5,000,000 SCPs on an i7-7500U; ours are fit + locate scaled to "
        "all our SCPs.",
        "",
        md_table(["image", "SCOPs", "paper RMSE", "our RMSE", "paper dr_max", "our dr_max", "paper s",
                  "our s", "our PRM RMSE"], rows),
        "",
        verdict,
        missing_note(runner, ["lrm", "prm"]),
        "### MLP at the same SCOP counts (MLP paper, Figures 3-8)",
        "",
        "The MLP paper shows these runs only as figures; its text says 10 and 20 SCOPs never reached "
        "sub-pixel accuracy, 30 was not enough for ISB, SJB, SAN (5 neurons), and 100 SCOPs gave sub-pixel "
        "RMSE and dr_max on all ten images. Ours (RMSE / dr_max, px, default `mlp` parameters):",
        "",
        md_table(["preset"] + [f"{k} SCOPs" for k in SCOP_COUNTS], mlp_rows),
        "",
    ]
    mlp100 = [r for r in runs if r["method"] == "mlp" and r["n_scops"] == 100 and not r.get("error")]
    if mlp100:
        sub = all(r["dr_max_px"] is not None and r["dr_max_px"] < 1 for r in mlp100)
        runner.verdict("MLP paper Figs. 3-8 (MLP, 100 SCOPs sub-pixel everywhere)",
                       "reproduced" if sub else "not reproduced",
                       f"RMSE {rng_str([r['rmse_px'] for r in mlp100])} px, dr_max "
                       f"{rng_str([r['dr_max_px'] for r in mlp100])} px at 100 SCOPs")
        out.append(f"**Verdict: {'reproduced' if sub else 'not reproduced'}** (100 SCOPs "
                   f"{'give' if sub else 'do not give'} sub-pixel dr_max on every preset run: "
                   f"RMSE {rng_str([r['rmse_px'] for r in mlp100])} px, dr_max "
                   f"{rng_str([r['dr_max_px'] for r in mlp100])} px).")
    out.append(missing_note(runner, ["mlp"]))
    return "\n".join(out)


def geometry_scenes(runner: Runner) -> list[tuple[str, str, str, object]]:
    """(label, orbit, attitude, scene): from the straight teaching orbit to the agile preset."""
    wsu = runner.scene("WSU")
    const_att = copy.deepcopy(wsu)
    const_att.exterior.attitude_coeffs[:, 1:] = 0.0
    straight = copy.deepcopy(wsu)
    straight.exterior.position_coeffs[:, 2:] = 0.0
    return [
        ("linear", "straight (constant velocity)", "constant", runner.scene("linear")),
        ("WSU-const-att", "Keplerian (WSU)", "constant (WSU's at t = 0)", const_att),
        ("WSU-straight", "straight (WSU's tangent)", "WSU's (orbit-following + body rates)", straight),
        ("WSU-no-body-rates", "Keplerian (WSU)", "orbit-following only", runner.scene("WSU", attitude_rate_scale=0.0)),
        ("WSU", "Keplerian (WSU)", "orbit-following + body rates", wsu),
        ("agile", "Keplerian (PMA)", "strong body rates and accelerations + jitter", runner.scene("agile")),
    ]


def section_geometry(runner: Runner) -> str:
    """Where does the LRM reach the paper's 1e-9 px?"""
    rows = []
    lin = None
    curved = []
    for label, orbit, att, scene in geometry_scenes(runner):
        runs = runner.run(scene, label, ["lrm", "prm"], SCOP_COUNTS, experiment="geometry")
        cells = [label, orbit, att]
        for k in SCOP_COUNTS:
            r = find(runs, method="lrm", n_scops=k)
            cells.append(ours(r, "rmse_px"))
        r = find(runs, method="prm", n_scops=100)
        cells.append(ours(r, "rmse_px"))
        rows.append(cells)
        lrm = [r["rmse_px"] for r in runs if r["method"] == "lrm" and not r.get("error")]
        if label == "linear":
            lin = lrm
        elif lrm:
            curved.append((label, max(lrm)))
    out = [
        "## Where the LRM reaches 1e-9 px: orbit and attitude",
        "",
        "LRM RMSE (px) for 10 / 30 / 50 / 100 SCOPs on scenes that differ only in the orbit and attitude model "
        "(WSU geometry; `WSU-const-att` and `WSU-straight` are the WSU scene with the attitude rates, "
        "respectively the orbit's acceleration, set to zero in the MPC polynomials). The last column is the "
        "PRM (degree 2) at 100 SCOPs.",
        "",
        md_table(["scene", "orbit", "attitude"] + [f"LRM {k}" for k in SCOP_COUNTS] + ["PRM 100"], rows),
        "",
    ]
    if lin:
        txt = (f"**Verdict:** with a straight orbit at constant attitude (`linear`) the LRM reaches {rng_str(lin)} px: "
               "the paper's 1e-9 px is reproduced there, and it is exact in principle: the condition x = 0 reads "
               "r1 . (P - S0 - V t) = 0, so t, hence the row, is affine in (X, Y) at a fixed height; what remains is "
               "floating-point rounding.")
        if curved:
            txt += (" As soon as the orbit is curved or the attitude changes with time the row is no longer affine: "
                    + "; ".join(f"`{lab}` up to {fmt(v)} px" for lab, v in curved)
                    + ". The ten paper presets are all of the curved kind, so the 1e-9 px of Table 3 does not come "
                    "out of a realistic MPC orbit (each of orbit curvature alone and attitude rates alone already "
                    "costs 3-6e-3 px); it is reproduced only by the straight-orbit, constant-attitude simulation.")
        out.append(txt)
        runner.verdict("LRM paper's 1e-9 px: under which orbit/attitude", "reproduced on `linear` only",
                       f"straight orbit + constant attitude: {rng_str(lin)} px; curved orbit or attitude rates: "
                       + ", ".join(f"{lab} {fmt(v)}" for lab, v in curved) + " px")
    out.append(missing_note(runner, ["lrm", "prm"]))
    return "\n".join(out)


def section_table4(runner: Runner, presets: list[str]) -> str:
    """LRM paper Table 4 and MLP paper Table 4: NR, BWS, ANN, OGP and the proposed LRM / MLP."""
    t4 = pt.LRM_TABLE4
    m4 = pt.MLP_TABLE4
    all_rows = []
    bws_nearest, bws_lower, nr_rmse = [], [], []
    ann_rmse, ogp_rmse, lrm_rmse = [], [], []
    mlp_isb = None
    for p in presets:
        scene = runner.scene(p)
        paper = {m: (rmse, ts, drmax, k) for m, rmse, ts, drmax, k in t4["datasets"][p]}
        runs = runner.run(scene, p, ["nr", "bws"], [], experiment="table4")
        runs += runner.run(scene, p, ["bws"], [], params={"bws": {"select": "lower"}}, experiment="table4",
                           variant="lower")
        for m in ("ann", "ogp", "lrm"):
            k = paper[m][3]
            runs += runner.run(scene, p, [m], [k], experiment="table4")
        runs += runner.run(scene, p, ["mlp"], [100], experiment="table4")
        for m, variant, label in (("nr", "", "NR"), ("bws", "", "BWS (nearest row)"),
                                  ("bws", "lower", "BWS (lower row)"), ("ann", "", "ANN-BSD"),
                                  ("ogp", "", "OGP-BSD"), ("lrm", "", "LRM"), ("mlp", "", "MLP (100 SCOPs)")):
            r = find(runs, method=m, variant=variant)
            pr = paper.get(m) if m != "mlp" else None
            if m == "mlp" and p in m4["datasets"]:
                pm = {x[0]: x for x in m4["datasets"][p]}["mlp"]
                pr = (pm[1], pm[2], pm[3], 100)
            if m == "bws" and variant == "lower":
                pr = paper["bws"]
            all_rows.append([p, label, pr[3] if pr and pr[3] else "-",
                             pr[0] if pr else "-", ours(r, "rmse_px"), pr[2] if pr else "-", ours(r, "dr_max_px"),
                             pr[1] if pr else "-", total_s(r) if r else "n/a", ours(r, "ce_evals_per_point")])
            if r and not r.get("error"):
                {"nr": nr_rmse, "ann": ann_rmse, "ogp": ogp_rmse, "lrm": lrm_rmse}.get(m, []).append(r["rmse_px"])
                if m == "mlp" and p == "ISB":
                    mlp_isb = r["rmse_px"]
                if m == "bws" and p not in aligned_presets([p], runner.n_scps):
                    (bws_lower if variant == "lower" else bws_nearest).append((r["rmse_px"], r["dr_max_px"]))
    out = [
        "## LRM paper Table 4 and MLP paper Table 4: NR, BWS, ANN-BSD, OGP-BSD, LRM, MLP",
        "",
        f"Sources: {pt.PAPERS['lrm']['cite']}, {t4['table']}; {pt.PAPERS['mlp']['cite']}, {m4['table']} "
        f"({m4['page']}; only its ISB block survived the text extraction). ANN, OGP and LRM are trained on the "
        "SCOP count the LRM paper lists per image; the MLP on 100 SCOPs (the MLP paper's choice). BWS is run "
        "twice: returning the nearest integer row (our default) and the lower row of the bracketing pair.",
        "",
        md_table(["preset", "method", "SCOPs (paper)", "paper RMSE", "our RMSE", "paper dr_max", "our dr_max",
                  "paper s", "our s", "our CE/pt"], all_rows),
        "",
    ]
    verdicts = [aligned_note(presets, runner.n_scps)]
    if nr_rmse:
        ok = max(nr_rmse) < 1e-8
        verdicts.append(f"- **NR: {'reproduced' if ok else 'not reproduced'}** (ours {rng_str(nr_rmse)} px vs the "
                        "paper's 2.5e-10 - 1.2e-9 px: both are the root to machine precision).")
        runner.verdict("LRM/MLP papers Table 4: NR", "reproduced" if ok else "not reproduced",
                       f"ours {rng_str(nr_rmse)} px vs 2.5e-10 - 1.2e-9 px")
    if bws_nearest:
        verdicts.append(
            f"- **BWS: reproduced once the row convention is matched.** Returning the nearest integer row gives "
            f"RMSE {rng_str([a for a, _ in bws_nearest])} px and dr_max {rng_str([b for _, b in bws_nearest])} px "
            "(a uniform rounding error: 1/sqrt(12) = 0.289 px, max 0.5), which is what the 2020 paper prints for "
            "BWS (0.30 / 0.29). The LRM and MLP papers print 0.56-0.60 px with dr_max 1: that is the lower "
            "row of the bracketing pair (a uniform error on [0, 1): RMSE 1/sqrt(3) = 0.577, max -> 1)"
            + (f", and our `select=\"lower\"` run gives RMSE {rng_str([a for a, _ in bws_lower])} px, dr_max "
               f"{rng_str([b for _, b in bws_lower])} px." if bws_lower else "."))
        runner.verdict("LRM/MLP papers Table 4: BWS", "reproduced (with the lower-row convention)",
                       f"lower row: {rng_str([a for a, _ in bws_lower])} px / dr_max "
                       f"{rng_str([b for _, b in bws_lower])} vs 0.56-0.60 / 1; nearest row gives 0.29 / 0.5")
    if ann_rmse or ogp_rmse:
        verdicts.append(
            f"- **ANN / OGP: not reproduced -- ours are far more accurate.** Ours: ANN {rng_str(ann_rmse)} px, OGP "
            f"{rng_str(ogp_rmse)} px vs the paper's 0.28-0.32 px (dr_max 0.52-0.81) on 200-1000 SCOPs. An "
            "affine approximation plus a smooth error model of a smooth function has no reason to stop at 0.3 "
            "px; 0.289 px is exactly the RMSE of rounding to an integer row (1/sqrt(12)), which suggests that the "
            "2021 method's targets or outputs were integer scanlines. That is a hypothesis: the 2021 paper itself "
            "(Adv. Space Res. 68:3584) is not among the papers we have.")
        runner.verdict("LRM/MLP papers Table 4: ANN-BSD, OGP-BSD", "not reproduced (ours better)",
                       f"ours ANN {rng_str(ann_rmse)} px, OGP {rng_str(ogp_rmse)} px vs 0.28-0.32 px "
                       "(= integer-row rounding, 0.289)")
    if lrm_rmse:
        runner.verdict("LRM/MLP papers Table 4: LRM", "not reproduced", f"ours {rng_str(lrm_rmse)} px vs 1.7e-10 - "
                       "2.3e-9 px (see the orbit/attitude section)")
    if mlp_isb is not None:
        ok = mlp_isb <= 0.03
        word = "reproduced" if ok else "sub-pixel, but above the paper's value" if mlp_isb < 1 else "not reproduced"
        verdicts.append(f"- **MLP (ISB, MLP paper Table 4): {word}** (ours {fmt(mlp_isb)} px RMSE at 100 SCOPs with "
                        "the default 1 x 10 network vs 0.015 px; the value depends on the initialisation and the "
                        "70/30 split, which the paper does not give).")
        runner.verdict("MLP paper Table 4: MLP on ISB", word, f"ours {fmt(mlp_isb)} px vs 0.015 px")
    verdicts.append("- **Times** are not comparable in absolute terms (another machine and language, and a "
                    "shared, noisy machine here), but the ordering holds: the learned methods locate all the "
                    "points in seconds without CEs for the row; the searches spend CEs per point (last column).")
    out += verdicts
    out.append(missing_note(runner, ["nr", "bws", "ann", "ogp", "lrm", "mlp"]))
    return "\n".join(out)


def section_mlp_table3(runner: Runner, quick: bool) -> str:
    """MLP paper Table 3: ISB, several MLP shapes and SCOP counts."""
    t = pt.MLP_TABLE3
    rows_spec = t["rows"]
    if quick:
        rows_spec = [r for r in rows_spec if (r[0], r[1], r[2]) in {(100, 1, 10), (500, 1, 30), (1000, 2, 10)}]
    scene = runner.scene("ISB")
    rows = []
    ok = []
    for k, layers, neurons, rmse, time_s, drmax, n_par in rows_spec:
        runs = runner.run(scene, "ISB", ["mlp"], [k], params={"mlp": {"hidden_layers": layers, "neurons": neurons}},
                          experiment="mlp_table3", variant=f"{layers}x{neurons}")
        r = runs[0] if runs else None
        rows.append([k, layers, neurons, n_par, rmse, ours(r, "rmse_px"), drmax, ours(r, "dr_max_px"), time_s,
                     total_s(r) if r else "n/a", ours(r, "fit_converged") if r else "n/a"])
        if r and not r.get("error"):
            ok.append((r, rmse))
    out = [
        "## MLP paper, Table 3: MLP shapes on ISB",
        "",
        f"Source: {pt.PAPERS['mlp']['cite']}, {t['table']} ({t['page']}). "
        + ("Quick mode: three rows of the table. " if quick else "")
        + "Note from the transcription: " + " ".join(t["notes"]),
        "",
        md_table(["SCOPs", "layers", "neurons", "parameters", "paper RMSE", "our RMSE", "paper dr_max",
                  "our dr_max", "paper s", "our s", "fit converged"], rows),
        "",
    ]
    if ok:
        sub = [r for r, _ in ok if r["dr_max_px"] is not None and r["dr_max_px"] < 1]
        le = [r for r, paper in ok if r["rmse_px"] is not None and r["rmse_px"] <= paper]
        runner.verdict("MLP paper Table 3 (MLP shapes on ISB)",
                       "reproduced" if len(sub) == len(ok) else f"{len(sub)} of {len(ok)} sub-pixel",
                       f"all {len(ok)} shapes run: {len(sub)} sub-pixel, {len(le)} at or below the paper's RMSE; ours "
                       f"{rng_str([r['rmse_px'] for r, _ in ok])} px vs 0.001 - 0.14 px")
        out.append(f"**Verdict:** {len(sub)} of {len(ok)} of our runs are sub-pixel in dr_max, as every row of the "
                   f"paper's table (it lists only its sub-pixel cases); our RMSE is at or below the paper's in "
                   f"{len(le)} of {len(ok)}. Individual numbers depend on the initialisation and the 70/30 split, "
                   "which the paper does not give, so row-by-row equality is not expected.")
    out.append(missing_note(runner, ["mlp"]))
    return "\n".join(out)


def section_bss2020(runner: Runner) -> str:
    """The 2020 (Persian) paper, Tables 2 and 4: SS, BWS and their interpolated variants, NR, hybrid."""
    methods = ["ss", "bws", "ss-interp", "bws-interp", "nr", "hybrid"]
    out = [
        "## 2020 paper (Persian), Tables 2 and 4: sequential / bisecting window search and their interpolation",
        "",
        f"Source: {pt.PAPERS['bss2020']['cite']}, Tables 2 and 4 (simulated points). The SPOT-3 (6000 x 6000) "
        "and RapidEye (12000 x 11980) scenes are not presets; the closest presets stand in: QII (6000 x 6000, "
        "for SPOT-3) and ISB (8300 x 8600, our largest, for RapidEye). The paper evaluates 35 / 32 points; we "
        "use the SCP grid (subsampled for the pixel-level searches, see 'SCPs').",
        aligned_note(["QII", "ISB"], runner.n_scps),
    ]
    summary = {}
    for table, preset in ((pt.BSS2020_TABLE2, "QII"), (pt.BSS2020_TABLE4, "ISB")):
        runs = runner.run(runner.scene(preset), preset, methods, [], experiment="bss2020")
        rows = []
        for m, _space, max_ce, rmse, _ts, rmse_i, _ts_i in table["rows"]:
            r = find(runs, method=m)
            ri = find(runs, method=f"{m}-interp") if m in ("ss", "bws") else None
            rows.append([m, max_ce, ours(r, "ce_evals_max"), rmse, ours(r, "rmse_px"),
                         rmse_i if rmse_i is not None else "-", ours(ri, "rmse_px") if ri else "-",
                         ours(ri, "ce_evals_max") if ri else "-", f"{ours(r, 'n_evaluated')}"])
            summary[(preset, m)] = r
            if ri:
                summary[(preset, f"{m}-interp")] = ri
        out += [f"### {table['table']} ({table['title']}) vs {preset}", "",
                md_table(["method", "paper max CE", "our max CE", "paper RMSE", "our RMSE", "paper RMSE interp",
                          "our RMSE interp", "our max CE interp", "SCPs"], rows), "",
                "Transcription notes: " + " ".join(table["notes"]), ""]
    v = []

    def get(p, m, k):
        r = summary.get((p, m))
        return None if (r is None or r.get("error")) else r.get(k)

    if get("QII", "bws", "rmse_px") is not None:
        v.append(f"- **SS / BWS at pixel level: reproduced** (ours {fmt(get('QII', 'bws', 'rmse_px'))} px on QII, "
                 f"{fmt(get('ISB', 'bws', 'rmse_px'))} px on ISB vs the paper's 0.30 / 0.29: the rounding error "
                 "of an integer row, 1/sqrt(12) = 0.289 px).")
    if get("QII", "bws-interp", "rmse_px") is not None:
        v.append(f"- **Interpolated SS / BWS (eq. 4): reproduced in kind** (ours "
                 f"{fmt(get('QII', 'bws-interp', 'rmse_px'))} px on QII, {fmt(get('ISB', 'bws-interp', 'rmse_px'))} "
                 "px on ISB vs 5.5e-8 / 7.6e-8): linear interpolation between the two bracketing lines leaves an "
                 "error of the order of the residual's curvature over one line, 1e-8 px here.")
    if get("QII", "ss", "ce_evals_max") is not None:
        v.append(f"- **Cost:** our SS spends up to {fmt(get('QII', 'ss', 'ce_evals_max'))} CEs per point on QII "
                 f"(paper 6000 on SPOT-3, the full scan) and BWS {fmt(get('QII', 'bws', 'ce_evals_max'))} (paper "
                 "15), NR " + f"{fmt(get('QII', 'nr', 'ce_evals_max'))} (paper 4), hybrid "
                 f"{fmt(get('QII', 'hybrid', 'ce_evals_max'))} (paper 3). Our counts include the one CE of the "
                 "column where a method computes it.")
    if get("QII", "nr", "rmse_px") is not None:
        v.append(f"- **NR / hybrid: reproduced** (NR {fmt(get('QII', 'nr', 'rmse_px'))} px, hybrid "
                 f"{fmt(get('QII', 'hybrid', 'rmse_px'))} px vs 4.7e-9 / 1.1e-7 on SPOT-3).")
    if get("QII", "bws", "rmse_px") is not None:
        runner.verdict("2020 paper Tables 2, 4: SS, BWS (pixel level)", "reproduced",
                       f"{fmt(get('QII', 'bws', 'rmse_px'))} / {fmt(get('ISB', 'bws', 'rmse_px'))} px vs 0.30 / 0.29")
    if get("QII", "bws-interp", "rmse_px") is not None:
        runner.verdict("2020 paper Tables 2, 4: SS/BWS + interpolation (eq. 4)", "reproduced",
                       f"{fmt(get('QII', 'bws-interp', 'rmse_px'))} / {fmt(get('ISB', 'bws-interp', 'rmse_px'))} px "
                       "vs 5.5e-8 / 7.6e-8")
    if get("QII", "nr", "rmse_px") is not None:
        runner.verdict("2020 paper Tables 2, 4: NR, hybrid; max CE per point", "reproduced",
                       f"NR {fmt(get('QII', 'nr', 'rmse_px'))} px, hybrid {fmt(get('QII', 'hybrid', 'rmse_px'))} px; "
                       "max CE SS, BWS, NR, hybrid "
                       + ", ".join(fmt(get("QII", m, "ce_evals_max")) for m in ("ss", "bws", "nr", "hybrid"))
                       + " vs 6000, 15, 4, 3")
    out += v
    out += ["", "Tables 3 and 5 use real control points (the RMSE includes the points' own errors) and are not "
            "reproducible by simulation; they are transcribed in `explorer/paper_tables.py`.",
            missing_note(runner, methods)]
    return "\n".join(out)


#: Where ``bpnn`` departs from Yue et al. (measured by hand, tests/methods/test_bpnn.py asserts it over seeds 0-7).
BP_DEPARTURE = (
    "**Where our `bpnn` departs from the paper:** by default its network is `LineOfSightNetwork` "
    "(`explorer/methods/bpnn.py`): the sigmoid layer sees the image position only and the height enters "
    "linearly, X and Y affine in Z at a fixed pixel as along a straight line of sight, with a slope affine in "
    "the image position. The paper's network, Z a third sigmoid input, is exact on its 5-layer grids (the table "
    "above) but nothing constrains it between the height layers of fewer: on the contract scene (WSU, 800 m "
    "relief, 200 SCOPs x 3 layers, 500 check points on the terrain, 6 nodes) it fits its layers to 1-14 cm "
    "at every seed yet is 0.6 m (seed 0) and 1,046 / 1,263 / 1,220 m (seeds 4 / 6 / 7) off at the check "
    "points' own heights: 0.40 px row max at seed 0, 18.9 / 0.9 / 5.2 px with 20 / 31 / 23 % of the points "
    "flagged at seeds 4 / 6 / 7. The line-of-sight network: <= 0.0003 px and no point flagged at those seeds "
    "(`network=\"free\"` restores the paper's). SCOPs on one height are fitted by the paper's network: there the "
    "line-of-sight one trained worse (Pleiades RPC, 100 SCOPs, seeds 0-5: 0.25-1.75 px RMS against 0.06-0.15 px).")


def section_bp(runner: Runner, quick: bool) -> str:
    """BP-network paper Tables 2-6: terrain-independent 10x10x5 / 5x5x5 grids, hidden nodes 2..7, vs RFM."""
    nodes = (4, 6) if quick else (2, 3, 4, 5, 6, 7)
    scene = runner.scene("ISB")
    rows = []
    bp = {}
    for h in nodes:
        runs = runner.run(scene, "ISB-3D", ["bpnn"], [100], n_scps=25, layers=5,
                          params={"bpnn": {"hidden": h, "network": "free"}}, experiment="bp",
                          variant=f"{h} nodes")
        r = runs[0] if runs else None
        if r and not r.get("error"):
            bp[h] = r
        paper = {row[0]: row for row in pt.BP_TABLE2["rows"]}.get(h)
        rows.append([f"BP, {h} nodes", r["n_scops_used"] if r else "n/a", ours(r, "n_evaluated"),
                     ours(r, "rmse_px"), ours(r, "dr_max_px"), ours(r, "col_rmse_px"), ours(r, "valid_frac"),
                     ours(r, "fit_converged") if r else "n/a", f"{paper[12]} / {paper[11]}" if paper else "-"])
    runs = runner.run(scene, "ISB-3D", ["rfm"], [], n_scps=25, layers=5, experiment="bp")
    rf = runs[0] if runs else None
    t6 = pt.BP_TABLE6["rows"][0]
    rows.append(["RFM (10x10x5 grid)", "(own grid)", ours(rf, "n_evaluated"), ours(rf, "rmse_px"),
                 ours(rf, "dr_max_px"), ours(rf, "col_rmse_px"), ours(rf, "valid_frac"), "-", f"{t6[12]} / {t6[11]}"])
    out = [
        "## BP-network paper, Tables 2-6: BP network vs RFM, terrain-independent grids",
        "",
        f"Source: {pt.PAPERS['bp']['cite']}, Tables 2-6 (GF-2, 29200-row images; errors are ground X / Y / "
        "'planarity' residuals of the image -> ground model, in pixels). Not reproducible as such: the sensor is "
        "not a preset and the paper maps image -> ground, while our `bpnn` answers ground -> image through the "
        "same network (here the paper's network literally, `network=\"free\"`: Z a third input of the sigmoid "
        "layer; the method's default is the line-of-sight network, see the note below the table). "
        "The analogue here: ISB with a 10 x 10 x 5 control grid (five height layers over +-500 m) "
        "and a 5 x 5 x 5 check grid, as in the paper, reporting our row RMSE / max and column RMSE (px) next to "
        "the paper's check-point planarity RMS / max (dataset 1, Table 2; RFM: Table 6, dataset 1).",
        "",
        md_table(["model", "control pts", "check pts", "our row RMSE", "our row max", "our col RMSE", "valid",
                  "fit converged", "paper planarity RMS / max"], rows),
        "",
    ]
    if bp:
        good = [h for h, r in bp.items() if r["dr_max_px"] is not None and r["dr_max_px"] < 0.2]
        txt = ("**Verdict (trend only: other sensor, other direction):** the paper needs >= 4 hidden nodes for "
               "sub-0.2 px errors; "
               + (f"ours reach a row max < 0.2 px with {', '.join(map(str, good))} node(s). " if good else
                  "none of our runs reaches a row max < 0.2 px (our `bpnn` inverts the image -> ground network "
                  "by Newton iterations, so the network's ground error is what limits the row). "))
        if rf and not rf.get("error"):
            txt += (f"The terrain-independent RFM: ours {fmt(rf['rmse_px'])} px row RMSE vs the paper's 0.04-0.06 px "
                    "planarity RMS. ")
        out.append(txt)
        runner.verdict("BP paper Tables 2-4, 6 (BP network vs RFM, 3-D grids)", "trend compared",
                       "nodes reaching < 0.2 px: " + (", ".join(map(str, good)) or "none")
                       + (f"; RFM {fmt(rf['rmse_px'])} px" if rf and not rf.get("error") else ""))
    out += ["", BP_DEPARTURE, "",
            "Table 5 (terrain-dependent, 100 real GCPs) is not reproducible. Transcription notes: "
            + " ".join(pt.BP_TABLE5["notes"][:2]) + " " + pt.BP_TABLE2["notes"][1],
            missing_note(runner, ["bpnn", "rfm"])]
    return "\n".join(out)


def section_relief(runner: Runner, quick: bool) -> str:
    """Relief 1000 m: what it does to (X, Y)-only learned models."""
    preset = "WSU"
    relief = 1000.0
    counts = (30, 100)
    exact = ["nr", "hybrid", "rfm"] if not quick else ["nr", "rfm"]
    learned = ["lrm", "prm", "mlp"]
    flat_scene, hilly_scene = runner.scene(preset), runner.scene(preset, relief_m=relief)
    flat = runner.run(flat_scene, preset, exact + learned, counts, experiment="relief", variant="flat")
    variants = {
        "(X, Y) only": {"use_height": False, "height_tolerance_m": 1e9},
        "(X, Y) only, guarded": {"use_height": False},
        "(X, Y, Z)": {"use_height": True},
    }
    hilly = runner.run(hilly_scene, preset, exact, counts, relief_m=relief, experiment="relief", variant="")
    for label, prm in variants.items():
        hilly += runner.run(hilly_scene, preset, learned, counts, relief_m=relief, experiment="relief",
                            variant=label, params={m: dict(prm) for m in learned if runner.has(m)})
    rows = []
    for r in hilly:
        f = find(flat, method=r["method"], n_scops=r["n_scops"])
        rows.append([r["method"], r["variant"] or "-", r["n_scops"] or "-", ours(f, "rmse_px"), ours(r, "rmse_px"),
                     ours(r, "dr_max_px"), ours(r, "col_rmse_px"), ours(r, "valid_frac")])
        if r["rmse_px"] is None and not r.get("error"):
            rows[-1][5:7] = ["-", "-"]
    z = hilly_scene.terrain
    spec = preset_spec(preset)
    pitch, gsd = float(spec["pitch_deg"]), float(spec["gsd_m"])
    disp = relief * math.tan(math.radians(abs(pitch))) / gsd
    out = [
        f"## Relief: {relief:.0f} m of synthetic terrain under {preset}",
        "",
        f"SCOPs and SCPs lie on a seeded synthetic relief of {relief:.0f} m amplitude (`build_scene('{preset}', "
        f"relief_m={relief:.0f})`, heights {z.min_height:.0f} .. {z.max_height:.0f} m); every method is given the "
        "true (X, Y, Z) of each point. The learned methods run three ways: '(X, Y) only' as in the papers (the "
        "height is ignored; the guard that refuses points off the training height is switched off so the error "
        "shows), '(X, Y) only, guarded' (the default guard: points more than 1 m off the SCOPs' mean height are "
        "refused, see 'valid'), and '(X, Y, Z)' (the height as a third input). Row errors in px:",
        "",
        md_table(["method", "inputs", "SCOPs", "flat RMSE", "relief RMSE", "relief dr_max", "relief col RMSE",
                  "valid"], rows),
        "",
    ]
    xy = [r for r in hilly if r["variant"] == "(X, Y) only" and not r.get("error") and r["rmse_px"] is not None]
    xyz = [r for r in hilly if r["variant"] == "(X, Y, Z)" and not r.get("error") and r["rmse_px"] is not None]
    ex = [r for r in hilly if r["method"] in ("nr", "hybrid") and not r.get("error") and r["rmse_px"] is not None]
    gen = [r for r in hilly if r["method"] == "rfm" and not r.get("error") and r["rmse_px"] is not None]
    txt = "**Verdict:** "
    if ex:
        txt += f"the collinearity searches stay exact on relief ({rng_str([r['rmse_px'] for r in ex])} px)"
        txt += (f"; the terrain-independent RFM (3-D grid) stays at {rng_str([r['rmse_px'] for r in gen])} px. "
                if gen else ". ")
    refused = [r for r in hilly if r["variant"] == "(X, Y) only" and r.get("fit_converged") is False]
    if xy:
        txt += (f"The (X, Y)-only learned models fall to {rng_str([r['rmse_px'] for r in xy])} px RMSE (dr_max up to "
                f"{fmt(max(r['dr_max_px'] for r in xy))} px): the scanline of a point moves with its height (relief "
                "displacement along track, about dZ tan(along-track view angle) / GSD: "
                f"{disp:.0f} px for dZ = {relief:.0f} m at {preset}'s {pitch:g} deg pitch and {gsd:g} m GSD), and a "
                "model of (X, Y) cannot know the height. The papers' protocol puts every point "
                "at the mean height and so never sees this. ")
        if refused:
            vals = [re.search(r"val\. ([0-9.eE+-]+)", refusal(r)) for r in refused]
            txt += ("The MLP refuses such a fit by itself (validation RMSE "
                    + ", ".join(f"{v.group(1)} px" for v in vals if v)
                    + " against its 1 px limit), so its points are marked not converged. ")
    if xyz:
        txt += (f"Given Z as an input (3-D training data, as the RFM and the BP network use), they recover "
                f"{rng_str([r['rmse_px'] for r in xyz])} px (a 'valid' below 1 there: SCPs whose height lies outside "
                "the range the SCOPs sampled, which the methods refuse rather than extrapolate).")
    out.append(txt)
    if xy:
        runner.verdict(f"Relief {relief:.0f} m (not in the papers)", "(X, Y)-only models break",
                       f"(X, Y)-only LRM/PRM/MLP {rng_str([r['rmse_px'] for r in xy])} px; with Z "
                       f"{rng_str([r['rmse_px'] for r in xyz])} px; NR/hybrid {rng_str([r['rmse_px'] for r in ex])} px")
    out.append(missing_note(runner, exact + learned))
    return "\n".join(out)


def section_habib(runner: Runner) -> str:
    t = pt.HABIB_TABLE2
    d = np.array([row[1:] for row in t["rows"]])
    rms = np.sqrt(np.mean(d**2, axis=0))
    sd = d.std(axis=0)
    nn = runner.run(runner.scene("QII"), "QII", ["nn-rfm", "rfm"], [500], experiment="habib")
    nn_rows = [[r["method"], r["n_scops_used"] or "(own grid)", ours(r, "rmse_px"), ours(r, "dr_max_px"),
                ours(r, "col_rmse_px"), ours(r, "fit_converged")] for r in nn]
    runner.verdict("Habib et al. Table 2", "not reproducible (real GPS points)",
                   "its 'RMS' row is the standard deviation; true RMS totals 1.59 / 1.13 m, not 1.55 / 1.09 m")
    rows = [["printed 'RMS'"] + list(t["rms"]), ["std about the mean (recomputed)"] + [round(float(v), 3) for v in sd],
            ["RMS about zero (recomputed)"] + [round(float(v), 3) for v in rms]]
    return "\n".join([
        "## Habib et al. 2018, Table 2 (not reproducible: real GPS check points)",
        "",
        f"Source: {pt.PAPERS['habib']['cite']}, {t['table']}. QuickBird with 572 matched GCPs and 9 GPS check "
        "points; nothing of it is simulated, so there is nothing to rerun. A check of the table's arithmetic from "
        "its nine residuals (metres):",
        "",
        md_table(["", "RFM err x", "RFM err y", "hybrid err x", "hybrid err y"], rows),
        "",
        "The row printed as RMS is the standard deviation about the mean; the totals in the text (1.55 m -> 1.09 m) "
        f"become {math.hypot(rms[0], rms[1]):.2f} m -> {math.hypot(rms[2], rms[3]):.2f} m as true RMS errors. The "
        "improvement claimed (RFM on irregular GCPs -> RFM on an MLP-regularised grid) stands either way.",
        "",
        "For orientation only, our simulated analogue on QII (QuickBird): `nn-rfm` (an MLP image -> ground trained "
        "on 500 SCOPs, a regular grid predicted by it, an RFM fitted on that grid) next to the terrain-independent "
        "`rfm` fitted on the rigorous model; row / column errors in px on the SCPs:",
        "",
        md_table(["method", "SCOPs", "row RMSE", "row max", "col RMSE", "fit converged"], nn_rows) if nn_rows
        else "_nn-rfm / rfm not in the registry._",
        "",
    ])


# ------------------------------------------------------------------------------------------------ main
def header(args, runner: Runner, elapsed: float) -> str:
    methods = sorted(runner.methods)
    reg = registry()
    lines = [
        "# Results: the papers' tables and ours",
        "",
        "<!-- generated by benchmarks/reproduce_papers.py; do not edit by hand -->",
        "",
        f"Generated {_dt.datetime.now().strftime('%Y-%m-%d %H:%M')} with **{args.scps:,} SCPs per preset** "
        f"(pixel-level searches and any method projected to take > 60 s: a seeded subsample of "
        f"{args.max_points_slow:,}){' in --quick mode (3 presets)' if args.quick else ''}, seed {args.seed}, in "
        f"{elapsed / 60:.1f} min on {platform.machine()} / {os.cpu_count()} CPUs / Python "
        f"{platform.python_version()}. "
        + ("This is the papers' full protocol." if args.scps >= 5_000_000 and not args.quick else
           "Run `python benchmarks/reproduce_papers.py` for the full protocol (5,000,000 SCPs per image)."),
        "",
        "**Timings are noisy:** the machine was shared with other engineers while this ran, so seconds are "
        "indicative only (accuracies and CE counts are not affected). The papers' times are for 5,000,000 SCPs on "
        "an Intel i7-7500U; ours are fit + locate time scaled to all the SCPs. The ground-to-image speed of each "
        "method, measured warm and alone, is in [performance.md](performance.md).",
        "",
        "Metrics (`explorer.evaluate`): RMSE and dr_max of the row (papers' Eqs. 4-5) over the valid points, "
        "column RMSE, collinearity evaluations (CE) per point. The papers' numbers are transcribed in "
        "`explorer/paper_tables.py` (table, page, and every garbled or inconsistent number flagged there).",
        "",
        "Methods in the registry when this ran: "
        + ", ".join(f"`{m}` ({reg[m].label})" for m in methods) + ".",
        "",
        "## Summary",
        "",
        md_table(["paper / table", "verdict", "numbers"], [list(v) for v in runner.verdicts]),
        "",
        "Reproduce one line yourself: `pushbroom bench --preset WSU --methods nr,bws,lrm,mlp --scops 10,30,50,100 "
        "--scps 5000000 --json out.json`.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scps", type=int, default=None, help="SCPs per preset (default 5,000,000; --quick: 20,000)")
    ap.add_argument("--quick", action="store_true", help="3 presets, 20,000 SCPs, fewer variants (minutes)")
    ap.add_argument("--max-points-slow", type=int, default=None,
                    help="subsample for slow methods (default 20,000; --quick: 500)")
    ap.add_argument("--presets", default=None, help="paper presets to run (default all ten; --quick: WSU,ISB,SCB)")
    ap.add_argument("--sections", default="lrm,geometry,table4,mlp3,bss2020,bp,relief,habib",
                    help="comma-separated subset of the sections")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(ROOT / "docs" / "results.md"))
    ap.add_argument("--json", default=None, help="also write every run record to this JSON file")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    if args.scps is None:
        args.scps = 20_000 if args.quick else 5_000_000
    if args.max_points_slow is None:
        args.max_points_slow = 500 if args.quick else 20_000
    presets = (args.presets.split(",") if args.presets else (["WSU", "ISB", "SCB"] if args.quick else PAPER_PRESETS))
    sections = [s.strip() for s in args.sections.split(",") if s.strip()]
    runner = Runner(args.scps, args.max_points_slow, args.seed, progress=not args.quiet)
    t0 = time.perf_counter()
    parts = []
    table = {
        "lrm": lambda: section_lrm(runner, presets),
        "geometry": lambda: section_geometry(runner),
        "table4": lambda: section_table4(runner, presets),
        "mlp3": lambda: section_mlp_table3(runner, args.quick),
        "bss2020": lambda: section_bss2020(runner),
        "bp": lambda: section_bp(runner, args.quick),
        "relief": lambda: section_relief(runner, args.quick),
        "habib": lambda: section_habib(runner),
    }
    for s in sections:
        if s not in table:
            ap.error(f"unknown section {s!r}; choose from {', '.join(table)}")
        if not args.quiet:
            print(f"section {s} ...", file=sys.stderr)
        parts.append(table[s]())
    elapsed = time.perf_counter() - t0
    doc = header(args, runner, elapsed) + "\n" + "\n\n".join(parts) + "\n"
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(doc)
    print(f"wrote {out} ({elapsed / 60:.1f} min, {len(runner.records)} runs)", file=sys.stderr)
    if args.json:
        Path(args.json).write_text(json.dumps({"version": 1, "runs": runner.records}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
