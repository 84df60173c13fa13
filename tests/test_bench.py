"""The benchmark runner (explorer.bench) and ``pushbroom bench`` on a tiny configuration.

Two stand-in methods are registered for these tests only (monkeypatched into the registry, removed after
each test), so the runner is tested independently of the methods under development: a pixel-level
bisection (``exactness="pixel"``, hence always subsampled) and an affine least-squares fit of the row on
(X, Y) (a learned method).  The metrics are checked against an independent recomputation from the exact
rows of the simulated points.
"""

from __future__ import annotations

import json
import logging
import re

import numpy as np
import pytest

from explorer import bench
from explorer.cli import main
from explorer.errors import InputError
from explorer.methods import available, base
from explorer.methods.base import BestScanlineMethod
from explorer.points import simulate_points
from explorer.presets import build_scene


class PixelBisect(BestScanlineMethod):
    """Bisection of the along-track residual over the image rows, rounded to the integer row."""

    name = "_bench_pixel"
    label = "test pixel bisection"
    family = "search"
    needs_fit = False
    exactness = "pixel"

    def _locate(self, ground, *, trace):
        n = ground.shape[0]
        lo = np.full(n, -0.5)
        hi = np.full(n, self.scene.n_rows - 0.5)
        flo = self.scene.along_track_residual(ground, self.scene.scanline_time(lo))
        for _ in range(45):
            mid = 0.5 * (lo + hi)
            fm = self.scene.along_track_residual(ground, self.scene.scanline_time(mid))
            same = np.sign(fm) == np.sign(flo)
            lo, flo, hi = np.where(same, mid, lo), np.where(same, fm, flo), np.where(same, hi, mid)
        row = np.round(0.5 * (lo + hi))
        return self._result(ground, row, np.ones(n, bool), np.full(n, 46))


class AffineRow(BestScanlineMethod):
    """row = a0 + a1 X + a2 Y by least squares on the SCOPs (the LRM of Sensors 24:5594 in miniature)."""

    name = "_bench_affine"
    label = "test affine"
    family = "learned"
    needs_fit = True
    exactness = "approximate"

    def _fit(self, control):
        a = np.column_stack([np.ones(len(control)), control.ground[:, :2]])
        self.coef = np.linalg.lstsq(a, control.row, rcond=None)[0]
        self.fit_info["converged"] = True

    def _locate(self, ground, *, trace):
        row = self.coef[0] + ground[:, :2] @ self.coef[1:]
        n = ground.shape[0]
        return self._result(ground, row, np.ones(n, bool), np.zeros(n, int))


@pytest.fixture
def doubles(monkeypatch):
    base.registry()  # discover the real methods first
    monkeypatch.setitem(base._REGISTRY, PixelBisect.name, PixelBisect)
    monkeypatch.setitem(base._REGISTRY, AffineRow.name, AffineRow)
    return [PixelBisect.name, AffineRow.name]


def test_runs_schema_and_plan(doubles):
    res = bench.run_bench("WSU,linear", doubles, "10,30", 2000, max_points_slow=500, progress=False)
    runs = res.runs
    # search method once per preset (n_scops 0), learned once per preset and count
    assert [(r["preset"], r["method"], r["n_scops"]) for r in runs] == [
        ("WSU", "_bench_pixel", 0), ("WSU", "_bench_affine", 10), ("WSU", "_bench_affine", 30),
        ("linear", "_bench_pixel", 0), ("linear", "_bench_affine", 10), ("linear", "_bench_affine", 30),
    ]
    for r in runs:
        assert set(bench.RUN_FIELDS) <= set(r)
        assert r["error"] is None
        assert r["n_scps"] == len(simulate_points(build_scene(r["preset"]), 2000, kind="scp"))
        assert 0 < r["n_evaluated"] <= r["n_scps"]
        assert r["converged_frac"] == 1.0
    pix = [r for r in runs if r["method"] == "_bench_pixel"]
    aff = [r for r in runs if r["method"] == "_bench_affine"]
    # subsampling reported in n_evaluated: the pixel-level method is always subsampled
    assert all(r["n_evaluated"] == 500 and r["subsampled"] for r in pix)
    assert all(r["n_evaluated"] == r["n_scps"] and not r["subsampled"] for r in aff)
    assert all(r["ce_evals_per_point"] == 47 and r["ce_evals_max"] == 47 for r in pix)  # 46 + the column
    assert all(r["n_scops_used"] >= 4 and r["fit_converged"] is True for r in aff)
    # pixel rounding: RMSE of a uniform error on [-0.5, 0.5] is 1/sqrt(12) = 0.289
    assert all(abs(r["rmse_px"] - 12**-0.5) < 0.03 and r["dr_max_px"] <= 0.5 + 1e-9 for r in pix)
    # the affine model is exact on the straight-orbit, constant-attitude preset (Sensors 24:5594, Table 3)
    lin = [r for r in aff if r["preset"] == "linear"]
    assert all(r["rmse_px"] < 1e-6 for r in lin)
    json.dumps(res.doc, allow_nan=False)


def test_metrics_equal_independent_recomputation(doubles):
    res = bench.run_bench("WSU", doubles, [10], 1500, max_points_slow=400, seed=3, progress=False,
                          keep_evaluations=True)
    check = res.check["WSU"]
    scene = build_scene("WSU")
    for run, ev in zip(res.runs, res.evaluations, strict=True):
        idx = ev.evaluated_index
        assert idx.size == run["n_evaluated"] == ev.residual_row.size
        exact = check.row[idx]
        if run["method"] == "_bench_pixel":
            expected = np.round(exact) - exact  # the bisection brackets the exact row to < 1e-9
        else:
            ctrl = simulate_points(scene, 10, kind="scop")
            a = np.column_stack([np.ones(len(ctrl)), ctrl.ground[:, :2]])
            coef = np.linalg.lstsq(a, ctrl.row, rcond=None)[0]
            expected = coef[0] + check.ground[idx, :2] @ coef[1:] - exact
        tie = np.abs(np.abs(expected) - 0.5) < 1e-6  # rounding ties may go either way
        np.testing.assert_allclose(ev.residual_row[~tie], expected[~tie], atol=1e-6)
        rmse = np.sqrt(np.mean(expected**2))
        assert run["rmse_px"] == pytest.approx(rmse, rel=1e-6, abs=1e-9)
        assert run["dr_max_px"] == pytest.approx(np.max(np.abs(expected)), rel=1e-6, abs=1e-9)
        col = scene.column_at_row(check.ground[idx], exact + expected)
        assert run["col_rmse_px"] == pytest.approx(np.sqrt(np.mean((col - check.col[idx]) ** 2)), rel=1e-6,
                                                   abs=1e-9)


def test_subsample_is_seeded_and_pilot_triggers(doubles):
    a = bench.run_bench("linear", [doubles[0]], [10], 1000, max_points_slow=100, seed=5, progress=False,
                        keep_evaluations=True)
    b = bench.run_bench("linear", [doubles[0]], [10], 1000, max_points_slow=100, seed=5, progress=False,
                        keep_evaluations=True)
    np.testing.assert_array_equal(a.evaluations[0].evaluated_index, b.evaluations[0].evaluated_index)
    # a method whose measured throughput projects beyond slow_seconds is subsampled too
    c = bench.run_bench("linear", [doubles[1]], [10], 1000, max_points_slow=100, slow_seconds=0.0,
                        progress=False)
    assert c.runs[0]["n_evaluated"] == 100 and "pilot" in c.runs[0]["subsample_reason"]
    assert c.runs[0]["locate_s_full_est"] == pytest.approx(c.runs[0]["locate_s"] * c.runs[0]["n_scps"] / 100)


def test_relief_puts_points_on_the_terrain(doubles):
    res = bench.run_bench("WSU", [doubles[1]], [30], 500, relief_m=300.0, progress=False, keep_evaluations=True)
    z = res.check["WSU"].ground[:, 2]
    assert z.max() - z.min() > 100.0
    assert res.runs[0]["relief_m"] == 300.0 and res.doc["config"]["relief_m"] == 300.0


def test_cli_table_and_json(doubles, tmp_path, capsys):
    out = tmp_path / "b.json"
    rc = main(["bench", "--preset", "WSU,linear", "--methods", ",".join(doubles), "--scops", "10,30",
               "--scps", "2000", "--seed", "0", "--max-points-slow", "500", "--no-progress", "--json", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "RMSE px" in text and "_bench_affine" in text and "500/" in text
    doc = json.loads(out.read_text())
    assert doc["version"] == 1 and len(doc["runs"]) == 6
    for r in doc["runs"]:
        assert set(bench.RUN_FIELDS) <= set(r)
        assert isinstance(r["preset"], str) and isinstance(r["method"], str)
        assert isinstance(r["n_scops"], int) and isinstance(r["n_scps"], int) and isinstance(r["n_evaluated"], int)
        for k in ("rmse_px", "dr_max_px", "col_rmse_px", "fit_s", "locate_s", "ce_evals_per_point",
                  "converged_frac"):
            assert isinstance(r[k], float | int)


def test_cli_methods_all(doubles, monkeypatch, tmp_path):
    # 'all' means every registered method; the registry is narrowed to the two stand-ins so the test does not
    # depend on (or wait for) the methods under development
    monkeypatch.setattr(base, "_REGISTRY", {n: base._REGISTRY[n] for n in doubles})
    assert available() == doubles
    out = tmp_path / "all.json"
    rc = main(["bench", "--preset", "linear", "--methods", "all", "--scops", "10", "--scps", "300",
               "--max-points-slow", "100", "--no-progress", "--json", str(out)])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert [r["method"] for r in doc["runs"]] == doubles
    assert doc["config"]["methods"] == doubles


def test_unknown_method_or_preset_is_a_clear_error(doubles, capsys):
    assert main(["bench", "--preset", "WSU", "--methods", "nope", "--scps", "100"]) == 2
    err = capsys.readouterr().err
    assert "unknown method 'nope'" in err and "_bench_affine" in err
    assert main(["bench", "--preset", "NOPE", "--methods", doubles[0], "--scps", "100"]) == 2
    assert "unknown preset 'NOPE'" in capsys.readouterr().err
    with pytest.raises(InputError, match="SCOP count must be >= 4"):
        bench.run_bench("WSU", doubles, "2", 100, progress=False)


def test_failing_method_is_recorded_not_fatal(doubles, monkeypatch, caplog):
    def boom(self, control):
        raise RuntimeError("no convergence")

    monkeypatch.setattr(AffineRow, "_fit", boom)
    with caplog.at_level(logging.WARNING, logger="explorer"):  # one log line, not a warning record (issue 18)
        res = bench.run_bench("linear", doubles, [10], 300, progress=False)
    assert any(re.search("_bench_affine on linear .* failed", r.getMessage()) for r in caplog.records)
    bad = [r for r in res.runs if r["method"] == "_bench_affine"]
    assert bad[0]["error"] == "RuntimeError: no convergence" and bad[0]["rmse_px"] is None
    assert "ERROR RuntimeError" in bench.format_table(res.runs)


# ----------------------------------------------------------------------------- the transcribed paper tables
def _paper_tables():
    from explorer import paper_tables

    return paper_tables


def test_paper_tables_are_self_consistent():
    pt = _paper_tables()
    # MLP Table 3: the printed parameter count of an MLP (X, Y) -> row with L hidden layers of n neurons
    for _, layers, n, *_, n_par in pt.MLP_TABLE3["rows"]:
        assert n_par == 2 * n + n + (layers - 1) * (n * n + n) + n + 1
    # LRM Table 4's LRM column repeats Table 3 at the SCOP count it lists
    t3 = {(row[1], row[2]): row for row in pt.LRM_TABLE3["rows"]}
    for preset, rows in pt.LRM_TABLE4["datasets"].items():
        lrm = [r for r in rows if r[0] == "lrm"][0]
        assert t3[(preset, lrm[4])][3:6] == (lrm[1], lrm[2], lrm[3])
    # every LRM-paper image maps to a preset of the same size
    assert set(pt.LRM_IMAGE_TO_PRESET.values()) == set(pt.LRM_TABLE4["datasets"])
    # Habib Table 2: the printed 'RMS' row is the (population) standard deviation of the nine residuals
    d = np.array([r[1:] for r in pt.HABIB_TABLE2["rows"]])
    np.testing.assert_allclose(d.mean(axis=0), pt.HABIB_TABLE2["mean"], atol=1.5e-3)
    np.testing.assert_allclose(d.std(axis=0), pt.HABIB_TABLE2["rms"], atol=1.5e-3)
    for t in pt.ALL_TABLES.values():
        assert t["paper"] in pt.PAPERS and t["table"].startswith("Table") and t["page"]


def test_bench_cli_on_a_real_rpc(tmp_path, capsys):
    """``bench --rpc --as-mpc``: resection of a real Pleiades RPC, then the methods on that scene."""
    from explorer.cli import main

    out = tmp_path / "rpc.json"
    code = main(["bench", "--rpc", "tests/data/rpc/rpc_PLEIADES.xml", "--as-mpc", "--degree", "3", "--gcps", "49",
                 "--methods", "nr,lrm", "--scops", "30", "--scps", "2000", "--no-progress", "--json", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "GCPs: RMSE" in text
    runs = json.loads(out.read_text())["runs"]
    assert {r["method"] for r in runs} == {"nr", "lrm"}
    nr = next(r for r in runs if r["method"] == "nr")
    assert nr["preset"].startswith("rpc_PLEIADES.xml") and nr["rmse_px"] < 1e-8
    assert "stand-in" in nr["preset"] and "STAND-IN" in text
    doc = json.loads(out.read_text())
    assert doc["truth"].startswith("STAND-IN") and doc["stand_in"]["model"].startswith("the RPC itself")


def test_bench_cli_on_the_rpc_itself(tmp_path, capsys):
    """``bench --rpc``: the learned methods on the RPC itself (row and column against the RPC's own projection),
    the search methods skipped with the reason; the exit status stays 0."""
    from explorer.cli import main

    out = tmp_path / "rpc.json"
    code = main(["bench", "--rpc", "tests/data/rpc/rpc_PLEIADES.xml", "--methods", "nr,ogp,rfm", "--scops", "50",
                 "--scps", "2000", "--no-progress", "--json", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "truth: the RPC itself" in text and "SKIPPED method 'nr' searches the scanlines" in text
    doc = json.loads(out.read_text())
    runs = {r["method"]: r for r in doc["runs"]}
    assert "--as-mpc" in runs["nr"]["skipped"] and runs["nr"]["error"] is None
    for name in ("ogp", "rfm"):
        assert runs[name]["error"] is None and runs[name]["skipped"] is None
        assert runs[name]["rmse_px"] < 0.01 and runs[name]["col_rmse_px"] < 0.01, runs[name]


def test_a_method_the_sensor_cannot_serve_is_skipped_with_the_reason():
    """Issue 25 class 1: a search method on an RPC sensor (no scanlines) is recorded as skipped with the reason
    (not as an error, so the bench's exit status stays 0 and the other runs go on)."""
    from pathlib import Path

    from explorer.bench import format_table, run_one
    from explorer.points import simulate_points
    from explorer.presets import build_scene
    from explorer.rpc import read_rpc
    from explorer.rpc.sensor import RPCSensor

    rpc = RPCSensor(read_rpc(Path(__file__).parent / "data" / "rpc" / "rpc_IKONOS.txt"))
    check = simulate_points(build_scene("WSU"), 100, kind="scp")
    rec, ev = run_one(rpc, "exact", check, None, preset="ikonos", n_scops=0, n_scps_requested=100)
    assert ev is None and rec["error"] is None
    assert "'exact' searches the scanlines" in rec["skipped"] and "'rpc' has none" in rec["skipped"]
    assert "SKIPPED method 'exact'" in format_table([rec])
